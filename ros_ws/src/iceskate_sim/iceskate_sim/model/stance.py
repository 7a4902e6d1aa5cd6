"""The moving stance: a scheduled shift of the body after each support exchange (ROS-free).

After the support exchange at t_e the stance moves +dy1 forward and dz1 down over T1, then,
once the swing heel has struck at t_touchdown, a further +dy2 forward over T2 (smoothstep
ramps; docs/model.md, the posture stabiliser). Two controllers follow the same schedule: the
gait manager's posture reference moves the pelvis with it, and visual lifting shifts its head
target by it, so both are configured with this one value (the ramps run in the C++ laws).
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
