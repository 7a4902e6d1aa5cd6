"""Arm auxiliary input of steps 1-3 (seed §5.2, model-spec §7.5), ROS-free.

Before the 4th step the shoulders get an anti-phase sinusoid, tau_11 = +A sin(Phi) (a = 0) or
-A sin(Phi) (a = 1) and tau_14 = -tau_11, and the elbows and wrists a PD to 0. From the 4th step
on (``step_index`` >= 3 exchanges, model-spec §11 #21) every arm joint gets no torque at all.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math
from typing import Any

import numpy as np

from gait_manager._params import PHASE_READINGS, build, choice, integer, phase, real, zeros
from iceskate_sim.observation import Observation

RIGHT_SHOULDER, LEFT_SHOULDER = 11, 14
ELBOWS_AND_WRISTS = (12, 13, 15, 16)


@dataclass(frozen=True)
class ArmAssistParameters:
    """Parameters of the arm assist (model-spec §7.5 defaults).

    :param amplitude: A_arm [N m] of the shoulder sinusoid (2).
    :param period: T [s] of the phase (1.85, as eq. 10).
    :param phase: phase reading, as for the yaw input ('B' default; 'A', 'B_clipped').
    :param stiffness: K [N m/rad] of the elbow/wrist PD to 0 (10).
    :param damping: B [N m s/rad] of the elbow/wrist PD (1).
    :param off_from_step_index: all arm torques are 0 once ``step_index`` reaches this many
        exchanges (3: from the 4th step on, seed §5.2).
    """

    amplitude: float = 2.0
    period: float = 1.85
    phase: str = 'B'
    stiffness: float = 10.0
    damping: float = 1.0
    off_from_step_index: int = 3

    def __post_init__(self) -> None:
        """Validate every field (GaitManagerError naming the key)."""
        object.__setattr__(self, 'amplitude', real('amplitude', self.amplitude, low=0.0))
        object.__setattr__(self, 'period', real('period', self.period, low=0.0, open_low=True))
        choice('phase', self.phase, PHASE_READINGS)
        object.__setattr__(self, 'stiffness', real('stiffness', self.stiffness, low=0.0))
        object.__setattr__(self, 'damping', real('damping', self.damping, low=0.0))
        integer('off_from_step_index', self.off_from_step_index, low=0)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ArmAssistParameters:
        """Build from a mapping; unknown keys and bad values raise GaitManagerError."""
        return build(cls, d, 'arm_assist.')


def arm_assist_torque(obs: Observation, params: ArmAssistParameters) -> np.ndarray:
    """Return the arm assist torque [N m] on joints 11-16 (all 0 from the 4th step on)."""
    tau = zeros()
    if obs.step_index >= params.off_from_step_index:
        return tau
    sign = 1.0 if obs.a == 0 else -1.0
    phi = phase(params.phase, obs.t, obs.t_exchange, params.period)
    tau[RIGHT_SHOULDER] = sign * params.amplitude * math.sin(phi)
    tau[LEFT_SHOULDER] = -tau[RIGHT_SHOULDER]
    idx = list(ELBOWS_AND_WRISTS)
    tau[idx] = -params.stiffness * obs.q[idx] - params.damping * obs.v[idx]
    return tau
