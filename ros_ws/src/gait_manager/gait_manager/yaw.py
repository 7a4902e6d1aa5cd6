"""Torso-yaw input of the paper's eq. (10) (docs/model.md, torso yaw), ROS-free.

tau_8 = +A sin(Phi) while the right foot supports (a = 0) and -A sin(Phi) while the left foot
supports (a = 1), with Phi measured from the last support exchange t_e.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math
from typing import Any

import numpy as np

from gait_manager._params import PHASE_READINGS, phase, zeros
from gait_manager.errors import GaitManagerError
from iceskate_sim.observation import Observation
from iceskate_sim.parameters import check_fields, from_mapping, setting

YAW_JOINT = 8


@dataclass(frozen=True)
class YawParameters:
    """Parameters of the torso-yaw input, eq. (10) (docs/model.md, torso yaw). Each
    field's description, unit and range are its ``setting``."""

    amplitude: float = setting(30.0, 'A of eq. (10)', unit='N m', low=0.0)
    period: float = setting(1.85, 'T of eq. (10)', unit='s', low=0.0, open_low=True)
    phase: str = setting('B', "phase reading: 'B' Phi = 2 pi (t - t_e)/T, 'A' Phi = 2 (t - "
                         "t_e)/T (the literal text), 'B_clipped' reading B clipped to [0, pi]",
                         choices=PHASE_READINGS)

    def __post_init__(self) -> None:
        """Check and normalise every field (GaitManagerError naming the key)."""
        check_fields(self, GaitManagerError)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> YawParameters:
        """Build from a mapping; unknown keys and bad values raise GaitManagerError."""
        return from_mapping(cls, d, GaitManagerError, 'yaw.')


def yaw_phase(obs: Observation, params: YawParameters) -> float:
    """Phi [rad] of eq. (10) at ``obs.t``."""
    return phase(params.phase, obs.t, obs.t_exchange, params.period)


def yaw_torque(obs: Observation, params: YawParameters) -> np.ndarray:
    """Return the eq. (10) torque: only entry 8 (torso yaw) is nonzero [N m]."""
    tau = zeros()
    sign = 1.0 if obs.a == 0 else -1.0
    tau[YAW_JOINT] = sign * params.amplitude * math.sin(yaw_phase(obs, params))
    return tau
