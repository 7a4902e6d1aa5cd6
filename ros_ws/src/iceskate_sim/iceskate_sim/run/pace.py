"""The pace of a run watched by a person: ``PaceClock`` holds simulated time to ``pace``
simulated seconds per wall second. The headless live view waits on it between blocks, the
simulator node steps by it (lockstep or free-running); docs/usage.md, "Watch the robot"."""

from __future__ import annotations

import math
import time

#: Fastest pace a run is held to [simulated s per wall s].
MAX_PACE = 1000.0


class PaceClock:
    """When a simulated time is due at a pace, counted from an origin (wall, simulated time)
    set by the first question after ``restart`` (a new pace, a resume). Another thread (a
    page's control) may set the pace or restart it while one asks.

    :param pace: simulated seconds per wall second (0: no pace, everything is due at once).
    """

    def __init__(self, pace: float = 0.0) -> None:
        self._origin: tuple[float, float] | None = None
        self.pace = pace

    @property
    def pace(self) -> float:
        """Simulated seconds per wall second (0: none)."""
        return self._pace

    @pace.setter
    def pace(self, pace: float) -> None:
        if not (math.isfinite(pace) and pace >= 0.0):
            raise ValueError(f'a pace must be >= 0 (0: none), got {pace}')
        self._pace = float(pace)
        self._origin = None

    def restart(self) -> None:
        """Count from the next question on (after a pause: no catching up)."""
        self._origin = None

    def wait(self, t: float) -> float:
        """Wall seconds [s] until simulated time ``t`` [s] is due (0: it is)."""
        pace = self._pace  # read once: the page's thread may change it
        return 0.0 if pace <= 0.0 else max(0.0, -self._ahead(t, pace) / pace)

    def due(self, t: float, period: float, most: int) -> int:
        """Periods of ``period`` [s] due now from simulated time ``t`` [s] on, at most ``most``
        (no pace: ``most``)."""
        pace = self._pace
        if pace <= 0.0:
            return most
        return max(0, min(most, int(self._ahead(t, pace) / period + 1e-9)))

    def _ahead(self, t: float, pace: float) -> float:
        """Simulated seconds [s] due now beyond ``t`` at ``pace`` (negative: not yet)."""
        now = time.monotonic()
        origin = self._origin
        if origin is None:
            origin = self._origin = (now, t)
        wall, simulated = origin
        return (now - wall) * pace + simulated - t
