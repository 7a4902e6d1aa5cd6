"""Ending a run on a signal (``STOP_SIGNALS``, ``StopRequest``), child processes that never
outlive their parent (``die_with_parent``, ``process_alive``) and ``say``. See docs/usage.md,
'Ending a run early'.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
import threading
from types import FrameType
from typing import Any

from iceskate_sim.errors import RunInterrupted

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
_PR_SET_PDEATHSIG = 1


class StopRequest:
    """SIGINT, SIGTERM and SIGHUP become a request to stop, read by the run's loop."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self._saved: dict[int, Any] = {}

    def __enter__(self) -> StopRequest:
        """Install the handlers (main thread only)."""
        if threading.current_thread() is threading.main_thread():
            for signum in STOP_SIGNALS:
                self._saved[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        """Put the previous handlers back."""
        for signum, handler in self._saved.items():
            signal.signal(signum, handler)
        self._saved.clear()

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.signum is None:
            self.signum = signum

    @property
    def requested(self) -> bool:
        """A stop signal has arrived."""
        return self.signum is not None

    def error(self, t: float | None, detail: str = '') -> RunInterrupted:
        """The RunInterrupted of the signal that arrived, at simulation time t."""
        assert self.signum is not None
        return RunInterrupted(self.signum, t, detail)


def raise_if_stopped(stop: StopRequest | None, t: float | None = None, detail: str = '') -> None:
    """A long job's check between two of its steps.

    :raises RunInterrupted: once ``stop`` (None: never) has a signal, at simulation time ``t``
        [s] (None: none), saying ``detail`` (e.g. where the job was).
    """
    if stop is not None and stop.requested:
        raise stop.error(t, detail)


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` runs (False once it is gone, a zombie or dying)."""
    try:
        with open(f'/proc/{pid}/stat', encoding='ascii', errors='replace') as stat:
            state = stat.read().rsplit(')', 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ('Z', 'X', 'x')


def _load_prctl() -> Any:
    with contextlib.suppress(OSError, AttributeError):
        prctl = ctypes.CDLL(None, use_errno=True).prctl
        prctl.restype = ctypes.c_int
        return prctl
    return None


_prctl = _load_prctl()  # looked up before any fork: a preexec_fn may call it


def die_with_parent(signum: int = signal.SIGTERM, parent: int | None = None) -> bool:
    """Have the kernel send ``signum`` to this process when its parent ends.

    Safe in a ``preexec_fn`` (no allocation beyond the call). If ``parent`` (the pid expected as
    the parent) is already gone, the signal is sent at once.

    :returns: whether the kernel took the request (False where prctl is missing: not Linux).
    """
    if _prctl is None or _prctl(_PR_SET_PDEATHSIG, int(signum), 0, 0, 0) != 0:
        return False
    if parent is not None and os.getppid() != parent:
        os.kill(os.getpid(), signum)
    return True


def say(text: str) -> None:
    """One line on stderr (nothing if stderr is gone: a closed terminal)."""
    with contextlib.suppress(OSError, ValueError):
        print(text, file=sys.stderr, flush=True)
