"""The moving stance: a scheduled shift of the body after each support exchange (ROS-free).

After the support exchange at t_e the stance moves +dy1 forward and dz1 down over T1, then,
once the swing heel has struck at t_touchdown, a further +dy2 forward over T2 (smoothstep
ramps; docs/model.md, the posture stabiliser). Two controllers follow the same schedule: the
gait manager's posture reference moves the pelvis with it, and visual lifting shifts its head
target by it, so both share this one function.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from iceskate_sim.model.observation import Observation


def smoothstep(x: float) -> float:
    """3x^2 - 2x^3 on [0, 1], clamped outside."""
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


def ramp(dt: float, duration: float) -> float:
    """A smoothstep from 0 to 1 over ``duration`` [s] after ``dt`` = 0 (a step if 0 s)."""
    if duration == 0.0:
        return 1.0 if dt >= 0.0 else 0.0
    return smoothstep(dt / duration)


@dataclass(frozen=True)
class StanceSchedule:
    """The shift schedule: dy1 [m] forward and dz1 [m] down over T1 [s] after t_e, then dy2
    [m] forward over T2 [s] after the heel strike."""

    dy1: float
    dz1: float
    t1: float
    dy2: float
    t2: float

    def shift(self, obs: Observation) -> np.ndarray:
        """(dy, dz) [m] of the stance at ``obs`` (dz < 0 is down)."""
        s1 = ramp(obs.t - obs.t_exchange, self.t1)
        dy = self.dy1 * s1
        dz = -self.dz1 * s1
        if math.isfinite(obs.t_touchdown):
            dy += self.dy2 * ramp(obs.t - obs.t_touchdown, self.t2)
        return np.array([dy, dz])
