"""The moving stance's schedule, ``StanceSchedule`` (m, s), which the controllers that follow
the stance share (the ramps run in the C++ laws). See docs/model.md §11.2.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class StanceSchedule:
    """The shift schedule: dy1 [m] forward and dz1 [m] down over T1 [s] after t_e, then dy2
    [m] forward over T2 [s] after the heel strike."""

    dy1: float
    dz1: float
    t1: float
    dy2: float
    t2: float
