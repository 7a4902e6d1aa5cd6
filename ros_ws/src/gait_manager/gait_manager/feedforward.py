"""Feed-forward leg torques (joints 1, 2, 3, 5, 6; docs/model.md, feed-forward pulses) and
weight transfer (docs/model.md, weight transfer), ROS-free.

Feed-forward (the paper, Sec. 5.2: "feed-forward-like" torques on joints 1, 2, 3 for push-off
and 5 for the swing), event-triggered, measured from the last support exchange t_e:

* swing hip, while the swing foot is in the air (code 'A'): tau_5 = A5 sin(pi (t - t_e)/D5)
  on [t_e, t_e + D5];
* swing knee, in the air: a flexion pulse tau_6 = -A6 sin(pi (t - t_e)/D6) on [t_e, t_e + D6],
  then an extension PD tau_6 = K6 (q6_ref - q6) - B6 dq6 until touchdown;
* push-off while the support foot stands on its toe pivot (q1 active, pivot 'toe'):
  tau_2 = +A2 (plantar flexion), tau_3 = -A3 (knee extension), tau_1 = -A1 (heel up; switch).

Weight transfer: tau_wt = -J_c^T f_des - j_r^T tau_n,des is a joint-torque realisation of a
desired contact force. J_c is the z row of the swing-heel Jacobian and j_r = dC_fr/dq (ones on
q1..q7). Applied with the swing heel on the floor, the torques press the heel down by f_des; in
a mode whose constraints contain the heel's z row (and C_fr), the constraint force grows by
exactly f_des (and tau_n by tau_n,des) and the accelerations do not change: load moves from the
support foot to the front foot. f_des ramps from 0 to share m g over ``ramp_time`` after the
heel strike t_touchdown ('ramp' rule); tau_n,des = moment_arm f_des while the sole is flat
(Fs, Fp), which puts the front foot's centre of pressure ``moment_arm`` ahead of the heel.

The 'com' rule instead splits the weight as a static two-foot support would, rear centre of
pressure at the rear toe and front one at the front heel (tau_n,des = 0): f_des = m g
(y_x - y_rear_toe) / (y_front_heel - y_rear_toe), clipped to [share_min ramp, share], with
y_x = y_com + capture_gain v_com sqrt(z_com / g) (the capture point for a gain of 1). The rear
normal force reaches 0 (the exchange) when y_x passes the front heel, without pushing the
rear centre of pressure off its sole. While only the front heel touches (Hs, Hp) the share is
at most ``heel_share`` (the rear foot stays loaded until the front sole is flat). A swing foot
down behind the support heel (the old support foot touching again after an exchange) gets no
load: f_des = 0.
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
from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.observation import Observation
from iceskate_sim.parameters import check_fields, from_mapping, setting
from iceskate_sim.robot import SupportModel

WEIGHT_RULES = ('ramp', 'com')
PIVOT, ANKLE, KNEE, SWING_HIP, SWING_KNEE, SWING_ANKLE = 1, 2, 3, 5, 6, 7
GRAVITY = 9.81  # m/s^2


@dataclass(frozen=True)
class FeedforwardParameters:
    """Parameters of the feed-forward leg torques (docs/model.md, feed-forward pulses). Each
    field's description, unit and range are its ``setting``."""

    hip_amplitude: float = setting(40.0, 'A5, amplitude of the swing-hip pulse', unit='N m',
                                   low=0.0)
    hip_duration: float = setting(0.35, 'D5, duration of the swing-hip pulse', unit='s',
                                  low=0.0, open_low=True)
    knee_amplitude: float = setting(20.0, 'A6, amplitude of the swing-knee flexion pulse '
                                    '(15-25 work)', unit='N m', low=0.0)
    knee_duration: float = setting(0.25, 'D6, duration of the swing-knee pulse', unit='s',
                                   low=0.0, open_low=True)
    knee_stiffness: float = setting(50.0, 'K6 of the swing-knee extension PD after the pulse',
                                    unit='N m/rad', low=0.0)
    knee_reference: float = setting(-0.05, 'q6_ref of the swing-knee extension PD (slightly '
                                    'flexed)', unit='rad', low=-2.5, high=0.0)
    knee_damping: float = setting(5.0, 'B6 of the swing-knee extension PD', unit='N m s/rad',
                                  low=0.0)
    ankle_push: float = setting(20.0, 'A2, support-ankle push-off (plantar flexion)',
                                unit='N m', low=0.0)
    knee_push: float = setting(10.0, 'A3, support-knee extension during push-off', unit='N m',
                               low=0.0)
    pivot_push: float = setting(10.0, 'A1, heel-up torque on the floor pivot q1 during '
                                'push-off', unit='N m', low=0.0)
    joint1_torque: bool = setting(True, 'apply the q1 (floor pivot) entry at all')

    def __post_init__(self) -> None:
        """Check and normalise every field (GaitManagerError naming the key)."""
        check_fields(self, GaitManagerError)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> FeedforwardParameters:
        """Build from a mapping; unknown keys and bad values raise GaitManagerError."""
        return from_mapping(cls, d, GaitManagerError, 'feedforward.')


@dataclass(frozen=True)
class WeightTransferParameters:
    """Parameters of the weight transfer after heel strike (docs/model.md, weight transfer).
    Each field's description, unit and range are its ``setting``."""

    share: float = setting(1.0, 'final f_des as a fraction of the weight m g (1: full '
                           'transfer, the rear normal force reaches 0; 0.3 settles in double '
                           "support); the 'com' rule's upper bound", low=0.0, high=2.0)
    ramp_time: float = setting(0.5, 'time of the linear ramp of f_des from 0 after the heel '
                               'strike', unit='s', low=0.0)
    moment_arm: float = setting(0.05, 'tau_n,des / f_des while the front sole is flat (0 '
                                'disables)', unit='m', low=-0.26, high=0.26)
    joint1_torque: bool = setting(True, 'apply the q1 (floor pivot) entry while q1 is active')
    start_share: float = setting(0.5, 'f_des / (m g) on the second foot in the starting double '
                                 'support (weight shift before the first step)', low=0.0,
                                 high=1.0)
    start_ramp: float = setting(0.5, 'time over which the starting share falls linearly to 0 '
                                '(unloading the swing foot for lift-off); 0 holds it',
                                unit='s', low=0.0)
    rule: str = setting('ramp', "'ramp' (time ramp to share) or 'com' (static split by the "
                        'capture point)', choices=WEIGHT_RULES)
    capture_gain: float = setting(1.0, "'com' rule: weight of v sqrt(z/g) in y_x (1: the "
                                  'capture point)', low=0.0, high=5.0)
    share_min: float = setting(0.0, "'com' rule: lower bound of the share, reached linearly "
                               'over ramp_time after the heel strike', low=0.0, high=2.0)
    heel_share: float = setting(2.0, "'com' rule: upper bound of the share while only the "
                                'front heel touches (2: none)', low=0.0, high=2.0)

    def __post_init__(self) -> None:
        """Check and normalise every field (GaitManagerError naming the key)."""
        check_fields(self, GaitManagerError)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> WeightTransferParameters:
        """Build from a mapping; unknown keys and bad values raise GaitManagerError."""
        return from_mapping(cls, d, GaitManagerError, 'weight_transfer.')


def _pulse(amplitude: float, duration: float, dt: float) -> float:
    """Half sine amplitude sin(pi dt / duration) on [0, duration], 0 elsewhere."""
    if 0.0 <= dt <= duration:
        return amplitude * math.sin(math.pi * dt / duration)
    return 0.0


def feedforward_torque(obs: Observation, params: FeedforwardParameters) -> np.ndarray:
    """Return the feed-forward torques [N m] on joints 1, 2, 3 (push-off), 5, 6 (swing)."""
    tau = zeros()
    mode = obs.gait_mode
    dt = obs.t - obs.t_exchange
    if mode.swing == 'A':
        tau[SWING_HIP] = _pulse(params.hip_amplitude, params.hip_duration, dt)
        if dt <= params.knee_duration:
            tau[SWING_KNEE] = -_pulse(params.knee_amplitude, params.knee_duration, dt)
        else:
            tau[SWING_KNEE] = (params.knee_stiffness * (params.knee_reference - obs.q[SWING_KNEE])
                               - params.knee_damping * obs.v[SWING_KNEE])
    if mode.q1_active and obs.pivot == 'toe':
        tau[ANKLE] = params.ankle_push
        tau[KNEE] = -params.knee_push
        if params.joint1_torque:
            tau[PIVOT] = -params.pivot_push
    return tau


def desired_heel_force(obs: Observation, params: WeightTransferParameters,
                       total_mass: float) -> float:
    """f_des [N]: vertical floor force wanted on the swing heel (0 in the air or before
    touchdown), ramping linearly to share m g over ``ramp_time`` after t_touchdown; in the
    starting double support, start_share m g falling to 0 over ``start_ramp``."""
    if obs.gait_mode.swing == 'A' or not math.isfinite(obs.t_touchdown):
        return 0.0
    weight = total_mass * GRAVITY
    if obs.step_index == 0 and obs.t_touchdown <= obs.t_exchange:  # down since the start
        if params.start_ramp == 0.0:
            return params.start_share * weight
        return params.start_share * weight * max(0.0, 1.0 - (obs.t - obs.t_exchange)
                                                 / params.start_ramp)
    final = params.share * weight
    if params.ramp_time == 0.0:
        return final
    return final * min(max((obs.t - obs.t_touchdown) / params.ramp_time, 0.0), 1.0)


_SCRATCH: dict[int, tuple[SupportModel, pin.Data]] = {}


def scratch_data(support_model: SupportModel) -> pin.Data:
    """Pinocchio scratch data of one support model, made once (not thread-safe, like
    GaitDynamics; the model is kept referenced so that its id stays unique)."""
    entry = _SCRATCH.get(id(support_model))
    if entry is None or entry[0] is not support_model:
        entry = (support_model, support_model.new_data())
        _SCRATCH[id(support_model)] = entry
    return entry[1]


def swing_heel_z_row(obs: Observation, dynamics: GaitDynamics) -> np.ndarray:
    """J_c: d z_heel / d q, the z row of the swing-heel Jacobian (18 entries [m/rad, m/m];
    columns of locked coordinates 0)."""
    sm = dynamics.robot.support_model(obs.side, obs.pivot)
    data = scratch_data(sm)
    pin.computeJointJacobians(sm.model, data, obs.q)
    row = pin.getFrameJacobian(sm.model, data, sm.frame_ids['swing_heel'],
                               pin.LOCAL_WORLD_ALIGNED)[2].copy()
    mode = obs.gait_mode
    if not mode.y0_active:
        row[0] = 0.0
    if not mode.q1_active:
        row[PIVOT] = 0.0
    return row


def capture_split_force(obs: Observation, dynamics: GaitDynamics,
                        params: WeightTransferParameters) -> float:
    """f_des [N] of the 'com' rule (see module); 0 with the swing foot in the air."""
    if obs.gait_mode.swing == 'A':
        return 0.0
    sm = dynamics.robot.support_model(obs.side, obs.pivot)
    data = scratch_data(sm)
    pin.centerOfMass(sm.model, data, obs.q, obs.v)
    pin.updateFramePlacements(sm.model, data)
    com, com_v = data.com[0], data.vcom[0]
    rear_toe = data.oMf[sm.frame_ids['support_toe']].translation[1]
    front_heel = data.oMf[sm.frame_ids['swing_heel']].translation[1]
    if front_heel <= data.oMf[sm.frame_ids['support_heel']].translation[1]:
        return 0.0  # the swing foot is down behind the support: no load goes onto it
    y_x = com[1] + params.capture_gain * com_v[1] * math.sqrt(max(com[2], 0.0) / GRAVITY)
    share = min(max((y_x - rear_toe) / max(front_heel - rear_toe, 0.02), 0.0), params.share)
    since = obs.t - obs.t_touchdown
    floor = params.share_min * (min(since / params.ramp_time, 1.0) if params.ramp_time > 0.0
                                else 1.0)
    fraction = max(share, floor)
    if obs.gait_mode.swing in ('Hs', 'Hp'):  # only the front heel touches
        fraction = min(fraction, params.heel_share)
    return fraction * dynamics.robot.total_mass * GRAVITY


def weight_transfer_torque(obs: Observation, dynamics: GaitDynamics,
                           params: WeightTransferParameters) -> np.ndarray:
    """Return tau_wt = -J_c^T f_des - j_r^T tau_n,des [N m] (zero before touchdown)."""
    tau = zeros()
    if params.rule == 'com' and obs.t_touchdown > obs.t_exchange:
        force = capture_split_force(obs, dynamics, params)
    else:
        force = desired_heel_force(obs, params, dynamics.robot.total_mass)
    if force == 0.0:
        return tau
    tau -= force * swing_heel_z_row(obs, dynamics)
    mode = obs.gait_mode
    if params.rule == 'ramp' and mode.swing in ('Fs', 'Fp') and params.moment_arm != 0.0:
        tau[PIVOT:SWING_ANKLE + 1] -= params.moment_arm * force
    tau[0] = 0.0
    if not (mode.q1_active and params.joint1_torque):
        tau[PIVOT] = 0.0
    return tau
