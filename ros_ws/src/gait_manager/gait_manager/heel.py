"""Heel-first landing input on the swing ankle, joint 7 (docs/model.md, heel-first landing),
ROS-free.

In the air (swing code 'A') a PD drives the swing-sole pitch theta_sf = q1 + ... + q7 (q1 only
while active; q0 = 0) to a landing pitch that ramps from 0 to theta_land (toe up) after t_e:
tau_7 = K7 (theta_land(t) - theta_sf) - B7 d(theta_sf)/dt. With the heel on the floor (Hs, Hp) a
softer PD lowers the sole to theta_sf = 0; with the sole flat (Fs, Fp) the constraint C_fr holds
it and the input is 0. Positive pitch lifts the toe (docs/model.md, world frame and angle
signs).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gait_manager._params import zeros
from gait_manager.errors import GaitManagerError
from iceskate_sim.observation import Observation
from iceskate_sim.parameters import check_fields, from_mapping, setting

SWING_ANKLE = 7


@dataclass(frozen=True)
class HeelParameters:
    """Parameters of the heel-first landing input (docs/model.md, heel-first landing). Each
    field's description, unit and range are its ``setting``."""

    stiffness: float = setting(150.0, 'K7 of the swing-sole pitch PD in the air (30 lets the '
                               'toe scuff)', unit='N m/rad', low=0.0)
    damping: float = setting(6.0, 'B7 of the swing-sole pitch PD in the air', unit='N m s/rad',
                             low=0.0)
    landing_pitch: float = setting(0.15, 'theta_land, landing sole pitch (toe up)', unit='rad',
                                   low=-0.5, high=0.5)
    ramp_time: float = setting(0.15, 'time over which theta_land ramps linearly from 0 after '
                               'the exchange', unit='s', low=0.0)
    contact_stiffness: float = setting(30.0, 'K of the PD to a flat sole with the heel on the '
                                       'floor (Hs, Hp)', unit='N m/rad', low=0.0)
    contact_damping: float = setting(3.0, 'B of the PD to a flat sole with the heel on the '
                                     'floor', unit='N m s/rad', low=0.0)

    def __post_init__(self) -> None:
        """Check and normalise every field (GaitManagerError naming the key)."""
        check_fields(self, GaitManagerError)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> HeelParameters:
        """Build from a mapping; unknown keys and bad values raise GaitManagerError."""
        return from_mapping(cls, d, GaitManagerError, 'heel.')


def swing_sole_pitch(obs: Observation) -> tuple[float, float]:
    """theta_sf [rad] and its rate [rad/s]: sum of q1 (if active) .. q7."""
    first = 1 if obs.gait_mode.q1_active else 2
    return (float(obs.q[first:SWING_ANKLE + 1].sum()),
            float(obs.v[first:SWING_ANKLE + 1].sum()))


def landing_pitch(obs: Observation, params: HeelParameters) -> float:
    """theta_land(t) [rad]: linear ramp from 0 at t_e to ``params.landing_pitch``."""
    if params.ramp_time == 0.0:
        return params.landing_pitch
    ratio = min(max((obs.t - obs.t_exchange) / params.ramp_time, 0.0), 1.0)
    return params.landing_pitch * ratio


def heel_torque(obs: Observation, params: HeelParameters) -> np.ndarray:
    """Return the heel-first input [N m]: only entry 7 (swing ankle) can be nonzero."""
    tau = zeros()
    swing = obs.gait_mode.swing
    if swing in ('Fs', 'Fp'):
        return tau
    theta, rate = swing_sole_pitch(obs)
    if swing == 'A':
        tau[SWING_ANKLE] = (params.stiffness * (landing_pitch(obs, params) - theta)
                            - params.damping * rate)
    else:  # 'Hs', 'Hp'
        tau[SWING_ANKLE] = -params.contact_stiffness * theta - params.contact_damping * rate
    return tau
