"""Times at a ROS stamp's resolution: ``builtin_interfaces/Time`` <-> integer nanoseconds <->
seconds. The lockstep compares stamps as integer nanoseconds, never as floats, and the
controllers' observation carries its times at this resolution, so a law computes the same
torque in-process as from a message. Duck-typed on the fields ``sec`` and ``nanosec``: rclpy and
rosbags messages alike.
"""

from __future__ import annotations

import math
from typing import Any

from iceskate_sim.errors import SimulationError

NS_PER_S = 1_000_000_000


def seconds_to_ns(t: float) -> int:
    """Simulation time t [s] as integer nanoseconds (rounded; the stamp of that instant)."""
    if not math.isfinite(t) or t < 0.0:
        raise SimulationError(f'a stamp needs a finite time >= 0 s, got {t!r}')
    return int(round(t * 1e9))


def ns_to_seconds(ns: int) -> float:
    """Seconds [s] of integer nanoseconds."""
    return ns / 1e9


def ns_to_sec_nanosec(ns: int) -> tuple[int, int]:
    """(sec, nanosec) fields of integer nanoseconds >= 0."""
    if ns < 0:
        raise SimulationError(f'a stamp needs a time >= 0, got {ns} ns')
    return ns // NS_PER_S, ns % NS_PER_S


def set_stamp(stamp: Any, ns: int) -> Any:
    """Write integer nanoseconds into a Time message in place; return it."""
    stamp.sec, stamp.nanosec = ns_to_sec_nanosec(ns)
    return stamp
