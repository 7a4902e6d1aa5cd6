"""Heel-first landing input on the swing ankle, joint 7 (model-spec §7.3, §14.3), ROS-free.

In the air (swing code 'A') a PD drives the swing-sole pitch theta_sf = q1 + ... + q7 (q1 only
while active; q0 = 0) to a landing pitch that ramps from 0 to theta_land (toe up) after t_e:
tau_7 = K7 (theta_land(t) - theta_sf) - B7 d(theta_sf)/dt. With the heel on the floor (Hs, Hp) a
softer PD lowers the sole to theta_sf = 0; with the sole flat (Fs, Fp) the constraint C_fr holds
it and the input is 0. Positive pitch lifts the toe (model-spec §1).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gait_manager._params import build, real, zeros
from iceskate_sim.observation import Observation

SWING_ANKLE = 7


@dataclass(frozen=True)
class HeelParameters:
    """Parameters of the heel-first input (model-spec §14.3 values).

    :param stiffness: K7 [N m/rad] in the air (150; §7.3's 30 lets the toe scuff).
    :param damping: B7 [N m s/rad] in the air (6).
    :param landing_pitch: theta_land [rad], toe up (0.15).
    :param ramp_time: time [s] over which theta_land ramps linearly from 0 after t_e (0.15).
    :param contact_stiffness: K [N m/rad] of the PD to theta_sf = 0 in Hs/Hp (30).
    :param contact_damping: B [N m s/rad] of that PD (3, the §7.3 ratio; an assumption).
    """

    stiffness: float = 150.0
    damping: float = 6.0
    landing_pitch: float = 0.15
    ramp_time: float = 0.15
    contact_stiffness: float = 30.0
    contact_damping: float = 3.0

    def __post_init__(self) -> None:
        """Validate every field (GaitManagerError naming the key)."""
        for name in ('stiffness', 'damping', 'contact_stiffness', 'contact_damping',
                     'ramp_time'):
            object.__setattr__(self, name, real(name, getattr(self, name), low=0.0))
        object.__setattr__(self, 'landing_pitch',
                           real('landing_pitch', self.landing_pitch, low=-0.5, high=0.5))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> HeelParameters:
        """Build from a mapping; unknown keys and bad values raise GaitManagerError."""
        return build(cls, d, 'heel.')


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
