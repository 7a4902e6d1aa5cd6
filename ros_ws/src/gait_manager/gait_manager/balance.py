"""Walking posture stabiliser: foot placement, swing-foot path and speed regulation, ROS-free.

The 'balance' reference of the posture stabiliser (model-spec §13.2 leaves the form open: "the
reference posture and the joint set must let the legs move"). The §7.1 feed-forward pulses
with the §14.4 moving stance reference did not sustain walking in this model (3-5 exchanges at
best, see scripts/tune_gait.py); this form, in the spirit of SIMBICON (Yin et al. 2007) and
Raibert's foot placement, does. Everything is a joint impedance (run by the simulator at its
physics rate) plus a feed-forward effort, recomputed at every control instant from the
observation only (world pitch angles phi_k = q1 + ... + q_k along the support-rooted chain):

* trunk: joints 9, 10 held at 0; the support hip q4 holds the pelvis pitch phi_4 at ``trunk``
  (world frame), with the swing-hip torque fed forward to cancel its reaction on the pelvis;
* support knee q3 and ankle q2: PD to ``stance_knee`` and -stance_knee/2 (hip over the
  ankle), blended from the current angles over ``blend`` s after each exchange;
* speed: a virtual horizontal force F = k_v (v_d - v_com) (-``max_brake`` <= F <=
  ``max_force``) at the centre of mass, realised as J_com,y^T F on the support joints 2, 3, 4
  (on ice a braking F only slides the support foot forward, hence its own bound);
* ankle strategy: the support ankle adds k_c (y_com - y_ankle - ``com_offset``) + b_c (v_com -
  v_ankle), which keeps the centre of mass over a gliding sole;
* gravity compensation g(q) on joints 2, 3, 4, 9, 10; torso-yaw centring spring on 8;
* swing leg in the air: the ankle follows a path from behind the hip to the landing point
  y_land = y_com + step_length/2 + placement_gain (v_com - v_d): it rises by ``clearance`` over
  the first ``lift_fraction`` of ``swing_time`` and descends from ``descent_start`` to
  ``press`` below the floor, so that the heel strikes; a 2-link IK (thigh, shank) gives the hip
  and knee references;
* double support (swing foot on the floor): the front knee is held straight-ish, the front
  hip is held at its angle of the control instant, and from the heel strike over
  ``push_ramp`` s the rear ankle PD gives way to a push-off torque ``push`` while the rear
  knee flexes to ``toe_off_flex``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math
from typing import Any

import numpy as np
import pinocchio as pin

from gait_manager._params import build, real, smoothstep, zeros
from gait_manager.errors import GaitManagerError
from gait_manager.feedforward import scratch_data
from iceskate_sim.command import JointCommand, all_finite
from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.observation import Observation

ANKLE_HEIGHT = 0.07  # m, ankle above the sole (model-spec §2.4)
THIGH, SHANK = 0.38, 0.40  # m, leg link lengths (Table 1)
SWING_START_BEHIND = 0.15  # m, start of the swing-ankle path behind the hip
GRAVITY_JOINTS = np.array([2, 3, 4, 9, 10])
SPEED_JOINTS = np.array([2, 3, 4])


@dataclass(frozen=True)
class BalanceParameters:
    """Walking stabiliser (values found by random search, see scripts/tune_gait.py).

    :param swing_time: duration [s] of the swing-foot path after the exchange.
    :param clearance: height [m] the swing ankle rises above its floor height.
    :param press: depth [m] below the floor the path ends at (makes the heel strike).
    :param lift_fraction: part of ``swing_time`` spent rising.
    :param descent_start: part of ``swing_time`` after which the path descends.
    :param step_length: nominal step [m]; the foot lands half of it ahead of the CoM.
    :param placement_gain: extra landing distance per m/s of speed error [s].
    :param speed: desired forward CoM speed v_d [m/s] (reached over the first 0.5 s).
    :param speed_gain: k_v [N s/m] of the virtual forward force.
    :param max_force: bound [N] of that force forward.
    :param max_brake: bound [N] of that force backward (on ice a backward floor force beyond
        mu N does not exist: a braking command only slides the support foot forward).
    :param com_stiffness: support-ankle feedback [N m/m] on the horizontal distance of the
        centre of mass ahead of the support ankle minus ``com_offset`` (ankle strategy; on a
        gliding foot it is the only way to keep the CoM over the sole).
    :param com_damping: its rate feedback [N m s/m] on (v_com - v_ankle).
    :param com_offset: desired distance [m] of the CoM ahead of the support ankle.
    :param stance_knee: support knee angle [rad] (flexion > 0).
    :param trunk: pelvis pitch phi_4 [rad] held in the world frame (> 0 leans back).
    :param stiffness: PD stiffness [N m/rad] of the support knee, hip and torso.
    :param ankle_stiffness: PD stiffness [N m/rad] of the support ankle.
    :param ankle_damping: its damping [N m s/rad].
    :param swing_stiffness: PD stiffness [N m/rad] of the swing hip and knee in the air.
    :param swing_damping: their damping [N m s/rad].
    :param front_hip_stiffness: [N m/rad] of the front hip in double support.
    :param front_knee_stiffness: [N m/rad] of the front knee in double support.
    :param push: rear-ankle push-off torque [N m] reached ``push_ramp`` s after heel strike.
    :param push_ramp: [s], see ``push``.
    :param toe_off_flex: rear knee angle [rad] reached at the end of ``push_ramp``.
    :param blend: time [s] over which support references move from the current angles to
        their nominal values after an exchange (no reference jump at the exchange).
    """

    swing_time: float = 0.45
    clearance: float = 0.04
    press: float = 0.02
    lift_fraction: float = 0.25
    descent_start: float = 0.6
    step_length: float = 0.3
    placement_gain: float = 0.2
    speed: float = 0.4
    speed_gain: float = 100.0
    max_force: float = 40.0
    max_brake: float = 40.0
    com_stiffness: float = 0.0
    com_damping: float = 0.0
    com_offset: float = 0.0
    stance_knee: float = 0.1
    trunk: float = 0.0
    stiffness: float = 800.0
    ankle_stiffness: float = 30.0
    ankle_damping: float = 5.0
    swing_stiffness: float = 300.0
    swing_damping: float = 30.0
    front_hip_stiffness: float = 300.0
    front_knee_stiffness: float = 300.0
    push: float = 20.0
    push_ramp: float = 0.3
    toe_off_flex: float = 0.5
    blend: float = 0.2

    def __post_init__(self) -> None:
        """Validate every field (GaitManagerError naming the key)."""
        bounds = {'swing_time': (0.05, 2.0), 'clearance': (0.0, 0.2), 'press': (0.0, 0.1),
                  'lift_fraction': (0.01, 1.0), 'descent_start': (0.0, 0.99),
                  'step_length': (0.0, 1.0), 'placement_gain': (-1.0, 1.0),
                  'speed': (-1.0, 2.0), 'stance_knee': (0.0, 1.5), 'trunk': (-0.5, 0.5),
                  'toe_off_flex': (0.0, 1.5), 'push': (-100.0, 200.0), 'blend': (0.0, 2.0),
                  'com_offset': (-0.2, 0.2)}
        for name, (low, high) in bounds.items():
            object.__setattr__(self, name, real(name, getattr(self, name), low, high))
        for name in ('speed_gain', 'max_force', 'max_brake', 'com_stiffness', 'com_damping',
                     'stiffness', 'ankle_stiffness',
                     'ankle_damping', 'swing_stiffness', 'swing_damping',
                     'front_hip_stiffness', 'front_knee_stiffness', 'push_ramp'):
            object.__setattr__(self, name, real(name, getattr(self, name), low=0.0))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> BalanceParameters:
        """Build from a mapping; unknown keys and bad values raise GaitManagerError."""
        return build(cls, d, 'balance.')


def leg_ik(d_y: float, d_z: float, thigh: float, shank: float) -> tuple[float, float]:
    """World pitch angles (phi_thigh, phi_shank) [rad] of a hanging 2-link leg whose ankle is
    at (d_y, d_z) [m] from the hip, knee forward (phi_thigh >= phi_shank); a link pointing
    down at angle phi has its far end at length (sin phi, -cos phi). Out of reach: straight
    leg pointing at the target."""
    reach = min(math.hypot(d_y, d_z), thigh + shank - 1e-9)
    cos_knee = (reach * reach - thigh * thigh - shank * shank) / (2.0 * thigh * shank)
    knee = math.acos(min(max(cos_knee, -1.0), 1.0))
    direction = math.atan2(d_y, -d_z)
    phi_thigh = direction + math.atan2(shank * math.sin(knee), thigh + shank * math.cos(knee))
    return phi_thigh, phi_thigh - knee


def swing_ankle_target(obs: Observation, params: BalanceParameters, hip_y: float,
                       com_y: float, com_vy: float) -> tuple[float, float]:
    """World (y, z) [m] of the swing-ankle path point at ``obs.t`` (see module)."""
    s = (obs.t - obs.t_exchange) / params.swing_time
    up = smoothstep(s / params.lift_fraction)
    down = smoothstep((s - params.descent_start) / (1.0 - params.descent_start))
    z = ANKLE_HEIGHT + params.clearance * up - (params.clearance + params.press) * down
    land = com_y + params.step_length / 2.0 + params.placement_gain * (com_vy - params.speed)
    start = hip_y - SWING_START_BEHIND
    return start + (land - start) * smoothstep(s), z


def balance_command(obs: Observation, dynamics: GaitDynamics, params: BalanceParameters,
                    yaw_stiffness: float, yaw_damping: float) -> JointCommand:
    """The walking stabiliser as a joint command (impedance + feed-forward effort), with the
    torso-yaw centring spring (``yaw_stiffness`` [N m/rad], ``yaw_damping`` [N m s/rad])."""
    q, v = obs.q, obs.v
    mode = obs.gait_mode
    sm = dynamics.robot.support_model(obs.side, obs.pivot)
    data = scratch_data(sm)
    pin.centerOfMass(sm.model, data, q, v)  # also places every joint
    com, com_v = data.com[0], data.vcom[0]
    phi3 = (q[1] if mode.q1_active else 0.0) + q[2] + q[3]
    phi4 = phi3 + q[4]
    K, B, R, effort = zeros(), zeros(), zeros(), zeros()

    def pd(j: int, stiffness: float, damping: float, reference: float) -> None:
        K[j], B[j], R[j] = stiffness, damping, reference

    p = params
    blend = smoothstep((obs.t - obs.t_exchange) / p.blend) if p.blend > 0.0 else 1.0
    pd(9, p.stiffness, 16.0, 0.0)
    pd(10, p.stiffness, 16.0, 0.0)
    pd(3, p.stiffness, 40.0, q[3] + blend * (p.stance_knee - q[3]))
    pd(2, p.ankle_stiffness, p.ankle_damping, q[2] + blend * (-p.stance_knee / 2.0 - q[2]))
    pd(4, p.stiffness, 80.0, p.trunk - phi3 - q[9] - q[10])
    pd(8, yaw_stiffness, yaw_damping, 0.0)
    ramp = min(obs.t / 0.5, 1.0)
    force = min(max(p.speed_gain * (p.speed * ramp - com_v[1]), -p.max_brake), p.max_force)
    jac_com_y = pin.jacobianCenterOfMass(sm.model, data, q)[1]
    effort[SPEED_JOINTS] += jac_com_y[SPEED_JOINTS] * force
    if p.com_stiffness or p.com_damping:
        ankle = sm.model.getJointId('q2')
        ankle_v = pin.getVelocity(sm.model, data, ankle, pin.LOCAL_WORLD_ALIGNED).linear
        effort[2] += (p.com_stiffness * (com[1] - data.oMi[ankle].translation[1] - p.com_offset)
                      + p.com_damping * (com_v[1] - ankle_v[1]))
    gravity = zeros()
    gravity[mode.active] = dynamics.gravity_terms(obs.contact(), q)
    effort[GRAVITY_JOINTS] += gravity[GRAVITY_JOINTS]
    if mode.swing == 'A':
        hip = data.oMi[sm.model.getJointId('q5')].translation
        y, z = swing_ankle_target(obs, p, hip[1], com[1], com_v[1])
        phi5, phi6 = leg_ik(y - hip[1], z - hip[2], THIGH, SHANK)
        pd(5, p.swing_stiffness, p.swing_damping, phi5 - phi4)
        pd(6, p.swing_stiffness, p.swing_damping, phi6 - phi5)
        effort[4] += p.swing_stiffness * (phi5 - phi4 - q[5]) - p.swing_damping * v[5]
    else:
        pd(6, p.front_knee_stiffness, 20.0, -0.05)
        pd(5, p.front_hip_stiffness, 20.0, q[5])  # held where it is at this instant
        if obs.t_touchdown > obs.t_exchange:
            r = min(max((obs.t - obs.t_touchdown) / p.push_ramp, 0.0), 1.0) \
                if p.push_ramp > 0.0 else 1.0
            K[2] *= 1.0 - r
            effort[2] += p.push * r
            R[3] = p.stance_knee + r * (p.toe_off_flex - p.stance_knee)
    if not (all_finite(effort) and all_finite(R)):
        raise GaitManagerError(f'balance command is not finite at t = {obs.t}')
    return JointCommand(effort, K, B, R)
