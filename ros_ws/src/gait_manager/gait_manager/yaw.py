"""Torso-yaw input of the paper's eq. (10) (model-spec §7.4), ROS-free.

tau_8 = +A sin(Phi) while the right foot supports (a = 0) and -A sin(Phi) while the left foot
supports (a = 1), with Phi measured from the last support exchange t_e.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math
from typing import Any

import numpy as np

from gait_manager._params import PHASE_READINGS, build, choice, phase, real, zeros
from iceskate_sim.observation import Observation

YAW_JOINT = 8


@dataclass(frozen=True)
class YawParameters:
    """Parameters of eq. (10).

    :param amplitude: A [N m] (seed eq. 10: 30).
    :param period: T [s] (seed: 1.85).
    :param phase: reading of the phase: 'B' Phi = 2 pi (t - t_e)/T (default, model-spec §7.4),
        'A' Phi = 2 (t - t_e)/T (the literal text), 'B_clipped' reading B clipped to [0, pi].
    """

    amplitude: float = 30.0
    period: float = 1.85
    phase: str = 'B'

    def __post_init__(self) -> None:
        """Validate every field (GaitManagerError naming the key)."""
        object.__setattr__(self, 'amplitude', real('amplitude', self.amplitude, low=0.0))
        object.__setattr__(self, 'period', real('period', self.period, low=0.0, open_low=True))
        choice('phase', self.phase, PHASE_READINGS)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> YawParameters:
        """Build from a mapping; unknown keys and bad values raise GaitManagerError."""
        return build(cls, d, 'yaw.')


def yaw_phase(obs: Observation, params: YawParameters) -> float:
    """Phi [rad] of eq. (10) at ``obs.t``."""
    return phase(params.phase, obs.t, obs.t_exchange, params.period)


def yaw_torque(obs: Observation, params: YawParameters) -> np.ndarray:
    """Return the eq. (10) torque: only entry 8 (torso yaw) is nonzero [N m]."""
    tau = zeros()
    sign = 1.0 if obs.a == 0 else -1.0
    tau[YAW_JOINT] = sign * params.amplitude * math.sin(yaw_phase(obs, params))
    return tau
