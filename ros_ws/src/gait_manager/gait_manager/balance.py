"""Walking posture stabiliser: foot placement, swing-foot path and speed regulation, ROS-free.

The 'balance' reference of the posture stabiliser (docs/model.md, walking stabiliser). The
feed-forward pulses with the moving stance reference did not sustain walking in this model
(3-5 exchanges at best, see scripts/tune_gait.py); this form, in the spirit of SIMBICON (Yin
et al. 2007) and Raibert's foot placement, does. Everything is a joint impedance (run by the
simulator at its physics rate) plus a feed-forward effort, recomputed at every control instant
from the observation only (world pitch angles phi_k = q1 + ... + q_k along the support-rooted
chain):

* trunk: joints 9, 10 held at 0; the support hip q4 holds the pelvis pitch phi_4 at ``trunk``
  (world frame), with the swing-hip torque fed forward to cancel its reaction on the pelvis;
* support knee q3 and ankle q2: PD to ``stance_knee`` and -stance_knee/2 (hip over the
  ankle), blended from the current angles over ``blend`` s after each exchange;
* speed: a virtual horizontal force F = F_0 + k_v (v_d - v_com) + k_p (y_H(0) + v_d t - y_H)
  (F_0 and v_d ramped in over 0.5 s; the speed and pace terms together within
  +-``feedback_limit`` if set; -``max_brake`` <= F <= ``max_force``) at the centre of
  mass, realised as J_com,y^T F on the support joints 2, 3, 4 (on ice a braking F only slides
  the support foot forward, hence its own bound); F_0 (``drive``) makes up for the ice's
  losses at speed, and the pace term (``pace_gain``) holds the head top y_H on the pace point
  that leaves its start y_H(0) at v_d, so the robot keeps the intended speed on average; the
  bound lets a pushed robot keep some of its new speed rather than brake its support foot out
  from under it;
* ankle strategy: the support ankle adds k_c (y_com - y_ankle - ``com_offset``) + b_c (v_com -
  v_ankle), which keeps the centre of mass over a gliding sole;
* gravity compensation g(q) on joints 2, 3, 4, 9, 10; torso-yaw centring spring on 8;
* swing leg in the air: the ankle follows a path from behind the hip to the landing point
  y_land = y_com + step_length/2 + placement_gain (v_com - v_d): it rises by ``clearance`` over
  the first ``lift_fraction`` of ``swing_time`` and waits behind the hip until ``glide_time``
  after the exchange (the support foot glides alone), then moves forward over ``swing_time``
  and descends from ``descent_start`` of it to ``press`` below the floor, so the heel strikes;
  a 2-link IK (thigh, shank) gives the hip and knee references;
* double support (swing foot on the floor): the front knee is held straight-ish (its
  reference at most ``front_knee_step`` from the current angle, if set), the front hip is held
  at its angle of the control instant, and from the heel strike over ``push_ramp`` s the rear
  ankle PD gives way to a push-off torque ``push`` while the rear knee flexes to
  ``toe_off_flex``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math
from typing import Any

import numpy as np
import pinocchio as pin

from gait_manager._params import zeros
from gait_manager.errors import GaitManagerError
from gait_manager.feedforward import scratch_data
from iceskate_sim.command import JointCommand, all_finite
from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.observation import Observation
from iceskate_sim.parameters import check_fields, from_mapping, setting
from iceskate_sim.stance import smoothstep

ANKLE_HEIGHT = 0.07  # m, ankle above the sole (docs/model.md, foot and other offsets)
THIGH, SHANK = 0.38, 0.40  # m, leg link lengths (Table 1)
SWING_START_BEHIND = 0.15  # m, start of the swing-ankle path behind the hip
FRONT_KNEE = -0.05  # rad, front knee reference in double support (nearly straight)
GRAVITY_JOINTS = np.array([2, 3, 4, 9, 10])
SPEED_JOINTS = np.array([2, 3, 4])


@dataclass(frozen=True)
class BalanceParameters:
    """Parameters of the walking stabiliser (values found by random search, see
    scripts/tune_gait.py). Each field's description, unit and range are its ``setting``."""

    swing_time: float = setting(0.45, 'duration of the swing-foot path after the exchange',
                                unit='s', low=0.05, high=2.0)
    glide_time: float = setting(0.0, 'time after the exchange the lifted swing foot waits '
                                'behind the hip before it swings forward (a glide on the '
                                'support foot)', unit='s', low=0.0, high=2.0)
    clearance: float = setting(0.04, 'height the swing ankle rises above its floor height',
                               unit='m', low=0.0, high=0.2)
    press: float = setting(0.02, 'depth below the floor the swing path ends at (makes the heel '
                           'strike)', unit='m', low=0.0, high=0.1)
    lift_fraction: float = setting(0.25, 'fraction of swing_time spent rising', low=0.01,
                                   high=1.0)
    descent_start: float = setting(0.6, 'fraction of swing_time after which the path descends',
                                   low=0.0, high=0.99)
    step_length: float = setting(0.3, 'nominal step; the foot lands half of it ahead of the '
                                 'CoM', unit='m', low=0.0, high=1.0)
    placement_gain: float = setting(0.2, 'extra landing distance per m/s of speed error',
                                    unit='s', low=-1.0, high=1.0)
    speed: float = setting(0.4, 'desired forward CoM speed v_d (reached over the first 0.5 s)',
                           unit='m/s', low=-1.0, high=2.0)
    speed_gain: float = setting(100.0, 'k_v of the virtual forward force', unit='N s/m',
                                low=0.0)
    pace_gain: float = setting(0.0, "virtual force per m the head top lags behind the pace "
                               "point, which leaves the head's start at t = 0 at speed v_d",
                               unit='N/m', low=0.0)
    feedback_limit: float = setting(0.0, 'bound of the speed and pace terms together (0: none): '
                                    'after a push the robot keeps some of the speed it got '
                                    'instead of braking, which on ice only slides the support '
                                    'foot forward', unit='N', low=0.0)
    drive: float = setting(0.0, 'constant part F_0 of the virtual force (reached over the '
                           "first 0.5 s): the push that makes up for the ice's losses at speed",
                           unit='N', low=-100.0, high=100.0)
    max_force: float = setting(40.0, 'bound of the virtual force forward', unit='N', low=0.0)
    max_brake: float = setting(40.0, 'bound of the virtual force backward (on ice braking only '
                               'slides the support foot forward)', unit='N', low=0.0)
    com_stiffness: float = setting(0.0, 'support-ankle feedback on the CoM distance ahead of '
                                   'the support ankle minus com_offset (ankle strategy)',
                                   unit='N m/m', low=0.0)
    com_damping: float = setting(0.0, 'support-ankle rate feedback on v_com - v_ankle',
                                 unit='N m s/m', low=0.0)
    com_offset: float = setting(0.0, 'desired distance of the CoM ahead of the support ankle',
                                unit='m', low=-0.2, high=0.2)
    stance_knee: float = setting(0.1, 'support knee angle (flexion > 0)', unit='rad', low=0.0,
                                 high=1.5)
    trunk: float = setting(0.0, 'pelvis pitch phi_4 held in the world frame (> 0 leans back)',
                           unit='rad', low=-0.5, high=0.5)
    stiffness: float = setting(800.0, 'PD stiffness of the support knee, hip and torso',
                               unit='N m/rad', low=0.0)
    ankle_stiffness: float = setting(30.0, 'PD stiffness of the support ankle', unit='N m/rad',
                                     low=0.0)
    ankle_damping: float = setting(5.0, 'PD damping of the support ankle', unit='N m s/rad',
                                   low=0.0)
    swing_stiffness: float = setting(300.0, 'PD stiffness of the swing hip and knee in the air',
                                     unit='N m/rad', low=0.0)
    swing_damping: float = setting(30.0, 'PD damping of the swing hip and knee in the air',
                                   unit='N m s/rad', low=0.0)
    front_hip_stiffness: float = setting(300.0, 'PD stiffness of the front hip in double '
                                         'support', unit='N m/rad', low=0.0)
    front_knee_stiffness: float = setting(300.0, 'PD stiffness of the front knee in double '
                                          'support', unit='N m/rad', low=0.0)
    push: float = setting(20.0, 'rear-ankle push-off torque reached push_ramp after the heel '
                          'strike', unit='N m', low=-100.0, high=200.0)
    push_ramp: float = setting(0.3, 'ramp time of the push-off torque and the rear knee flexion',
                               unit='s', low=0.0)
    toe_off_flex: float = setting(0.5, 'rear knee angle reached at the end of push_ramp',
                                  unit='rad', low=0.0, high=1.5)
    blend: float = setting(0.2, 'time over which the support references move from the current '
                           'angles to their nominal values after an exchange', unit='s',
                           low=0.0, high=2.0)
    front_knee_step: float = setting(0.0, 'largest distance of the front knee reference from '
                                     'the current angle in double support (0: no bound)',
                                     unit='rad', low=0.0, high=2.0)

    def __post_init__(self) -> None:
        """Check and normalise every field (GaitManagerError naming the key)."""
        check_fields(self, GaitManagerError)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> BalanceParameters:
        """Build from a mapping; unknown keys and bad values raise GaitManagerError."""
        return from_mapping(cls, d, GaitManagerError, 'balance.')


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
    elapsed = obs.t - obs.t_exchange
    up = smoothstep(elapsed / params.swing_time / params.lift_fraction)
    s = max(elapsed - params.glide_time, 0.0) / params.swing_time  # the forward path
    down = smoothstep((s - params.descent_start) / (1.0 - params.descent_start))
    z = ANKLE_HEIGHT + params.clearance * up - (params.clearance + params.press) * down
    land = com_y + params.step_length / 2.0 + params.placement_gain * (com_vy - params.speed)
    start = hip_y - SWING_START_BEHIND
    return start + (land - start) * smoothstep(s), z


def balance_command(obs: Observation, dynamics: GaitDynamics, params: BalanceParameters,
                    yaw_stiffness: float, yaw_damping: float,
                    head_start_y: float = 0.0) -> JointCommand:
    """The walking stabiliser as a joint command (impedance + feed-forward effort), with the
    torso-yaw centring spring (``yaw_stiffness`` [N m/rad], ``yaw_damping`` [N m s/rad]);
    ``head_start_y`` [m] is the head top's y at t = 0, the start of the pace point."""
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
    feedback = p.speed_gain * (p.speed * ramp - com_v[1])
    if p.pace_gain:
        head_y = dynamics.frame_placement(obs.contact(), q, 'head_top').translation[1]
        feedback += p.pace_gain * (head_start_y + p.speed * obs.t - head_y)
    if p.feedback_limit > 0.0:
        feedback = min(max(feedback, -p.feedback_limit), p.feedback_limit)
    force = min(max(p.drive * ramp + feedback, -p.max_brake), p.max_force)
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
        knee = FRONT_KNEE if p.front_knee_step == 0.0 else min(
            max(FRONT_KNEE, q[6] - p.front_knee_step), q[6] + p.front_knee_step)
        pd(6, p.front_knee_stiffness, 20.0, knee)
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
