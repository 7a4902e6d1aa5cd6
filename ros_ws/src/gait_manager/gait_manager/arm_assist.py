"""Arm auxiliary input of steps 1-3 (the paper, Sec. 5.2; docs/model.md §11.7), ROS-free.

Before the 4th step the shoulders get an anti-phase sinusoid, tau_11 = +A sin(Phi) (a = 0) or
-A sin(Phi) (a = 1) and tau_14 = -tau_11, and the elbows and wrists a PD to 0. From the 4th step
on (``step_index`` >= 3 exchanges) the assist lets the arms go: over the first ``release_time``
of that step each shoulder j = 11, 14 gets a brake -b (1 - S(t'/release_time)) v_j (b =
``release_damping``, t' the time since the exchange, S the smoothstep) that takes out the swing
the assist left, so that what the arms do next comes from the body alone; after it, and from
the next step on, no arm torque at all.
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
from iceskate_sim.stance import smoothstep

RIGHT_SHOULDER, LEFT_SHOULDER = 11, 14
ELBOWS_AND_WRISTS = (12, 13, 15, 16)
SHOULDERS = [RIGHT_SHOULDER, LEFT_SHOULDER]


@dataclass(frozen=True)
class ArmAssistParameters:
    """Parameters of the arm assist (docs/model.md, arm assist). Each field's description, unit
    and range are its ``setting``."""

    amplitude: float = setting(2.0, 'A_arm, amplitude of the shoulder sinusoid', unit='N m',
                               low=0.0)
    period: float = setting(1.85, 'T of the phase (as in eq. 10)', unit='s', low=0.0,
                            open_low=True)
    phase: str = setting('B', "phase reading, as for the yaw input: 'B' 2 pi (t - t_e)/T, 'A' "
                         "2 (t - t_e)/T, 'B_clipped' reading B clipped to [0, pi]",
                         choices=PHASE_READINGS)
    stiffness: float = setting(10.0, 'K of the elbow and wrist PD to 0', unit='N m/rad',
                               low=0.0)
    damping: float = setting(1.0, 'B of the elbow and wrist PD', unit='N m s/rad', low=0.0)
    off_from_step_index: int = setting(3, 'the assist stops once step_index reaches this many '
                                       'exchanges (3: from the 4th step on)', low=0)
    release_time: float = setting(0.0, 'duration of the shoulder brake at the start of the first '
                                  'step without assist (0: none)', unit='s', low=0.0)
    release_damping: float = setting(0.0, 'initial damping of the shoulder brake (joints 11, '
                                     '14), faded out over release_time', unit='N m s/rad',
                                     low=0.0)

    def __post_init__(self) -> None:
        """Check and normalise every field (GaitManagerError naming the key)."""
        check_fields(self, GaitManagerError)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> ArmAssistParameters:
        """Build from a mapping; unknown keys and bad values raise GaitManagerError."""
        return from_mapping(cls, d, GaitManagerError, 'arm_assist.')


def arm_assist_torque(obs: Observation, params: ArmAssistParameters) -> np.ndarray:
    """Return the arm assist torque [N m] on joints 11-16 (the release brake, then 0, from the
    4th step on)."""
    tau = zeros()
    if obs.step_index >= params.off_from_step_index:
        elapsed = obs.t - obs.t_exchange
        if obs.step_index == params.off_from_step_index and elapsed < params.release_time:
            fade = 1.0 - smoothstep(elapsed / params.release_time)
            tau[SHOULDERS] = -params.release_damping * fade * obs.v[SHOULDERS]
        return tau
    sign = 1.0 if obs.a == 0 else -1.0
    phi = phase(params.phase, obs.t, obs.t_exchange, params.period)
    tau[RIGHT_SHOULDER] = sign * params.amplitude * math.sin(phi)
    tau[LEFT_SHOULDER] = -tau[RIGHT_SHOULDER]
    idx = list(ELBOWS_AND_WRISTS)
    tau[idx] = -params.stiffness * obs.q[idx] - params.damping * obs.v[idx]
    return tau
