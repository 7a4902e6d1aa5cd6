"""``SummaryProcess``: draws a run's ``summary.png`` in a process forked before the run, which
imports matplotlib (about 0.7 s) while the run goes on, so that the picture at the end costs
only its drawing. A thread would share the GIL with the run's loop and slow it down.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
import contextlib
import multiprocessing
from multiprocessing.connection import Connection
import pathlib
import signal
from typing import Any

import numpy as np

from iceskate_sim.errors import SimulationError
from iceskate_sim.shutdown import STOP_SIGNALS, die_with_parent

#: Longest wait [s] for the picture once handed over (its drawing takes about 0.7 s).
DRAW_DEADLINE = 120.0
#: Longest wait [s] for the process to end once told to.
END_DEADLINE = 5.0


class SummaryProcess:
    """A forked process that draws ``summary.png`` when ``draw`` hands it a run's columns.

    Fork it before the parent starts threads (as the bag writer). It ignores the stop signals
    (the parent ends it), is killed when its parent dies (even by SIGKILL), and is ended by
    ``close``.
    """

    def __init__(self) -> None:
        context = multiprocessing.get_context('fork')
        self._connection, child = context.Pipe()
        self._process = context.Process(target=_serve, args=(child, self._connection),
                                        name='summary-picture', daemon=True)
        self._ready = False
        # the stop signals held until the process ignores them (a Ctrl-C at the fork would
        # end it with a traceback): it inherits the mask and unblocks them itself
        held = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
        try:
            self._process.start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, held)
        child.close()
        self.pid: int = self._process.pid

    def wait_ready(self, deadline: float = DRAW_DEADLINE) -> None:
        """Wait until the process has imported what it draws with (at most ``deadline`` s).

        :raises SimulationError: when it ended or did not get there in time.
        """
        if self._ready:
            return
        try:
            answer = self._connection.recv() if self._connection.poll(deadline) else None
        except (OSError, EOFError) as exc:
            raise SimulationError(f'the summary picture process ended early: {exc}') from None
        if answer != ('ready',):
            raise SimulationError(f'the summary picture process was not ready within '
                                  f'{deadline:g} s')
        self._ready = True

    def draw(self, columns: Iterable[tuple[str, np.ndarray]], metrics: Mapping[str, Any],
             path: pathlib.Path) -> pathlib.Path:
        """Draw ``path`` as ``summary.draw_summary`` does, in the process; wait for it.

        :raises SimulationError: when a column is missing, or the process failed or did not
            answer within ``DRAW_DEADLINE``.
        :raises OSError: when the picture cannot be written (its errno and message).
        """
        from iceskate_analysis.summary import picked_columns
        self.wait_ready()  # then it reads what is sent: the send cannot block for good
        try:
            self._connection.send((picked_columns(columns), dict(metrics), str(path)))
            answered = self._connection.poll(DRAW_DEADLINE)
            answer = self._connection.recv() if answered else None
        except (OSError, EOFError) as exc:
            raise SimulationError(f'the process drawing {path} ended early: {exc}') from None
        if answer is None:
            self.close()
            raise SimulationError(f'the process drawing {path} did not answer within '
                                  f'{DRAW_DEADLINE:g} s')
        kind, *detail = answer
        if kind == 'os_error':
            raise OSError(detail[0], detail[1], str(path))
        if kind == 'error':
            raise SimulationError(detail[0])
        return path

    def close(self) -> None:
        """End the process (idempotent); killed if it does not end within ``END_DEADLINE``."""
        if self._process is None:
            return
        process, self._process = self._process, None
        with contextlib.suppress(OSError):
            self._connection.send(None)
        process.join(END_DEADLINE)
        if process.is_alive():
            process.kill()
            process.join(END_DEADLINE)
        self._connection.close()


def _serve(connection: Connection, parent_end: Connection) -> None:
    """The process: import what the picture needs and say ('ready',), then draw each
    handed-over run until None (or the parent is gone), answering ('ok',), ('os_error', errno,
    message) or ('error', message)."""
    parent_end.close()
    for signum in STOP_SIGNALS:
        signal.signal(signum, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
    die_with_parent(signal.SIGKILL, multiprocessing.parent_process().pid)  # nothing to save
    with contextlib.suppress(Exception):  # an import that fails fails again, reported, below
        import matplotlib.backends.backend_agg  # noqa: F401
        import matplotlib.figure  # noqa: F401

        import iceskate_analysis.summary  # noqa: F401
    try:
        connection.send(('ready',))
    except OSError:
        return
    while True:
        try:
            item = connection.recv()
        except (EOFError, OSError):
            return
        if item is None:
            return
        columns, metrics, path = item
        try:
            from iceskate_analysis.summary import draw_picked
            draw_picked(columns, metrics, pathlib.Path(path))
            answer: tuple[Any, ...] = ('ok',)
        except OSError as exc:
            answer = ('os_error', exc.errno, exc.strerror or str(exc))
        except Exception as exc:  # reported to the parent, which raises it
            answer = ('error', f'{type(exc).__name__}: {exc}' if not isinstance(
                exc, SimulationError) else str(exc))
        try:
            connection.send(answer)
        except OSError:
            return
