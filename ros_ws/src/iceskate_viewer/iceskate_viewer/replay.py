"""The replay view of finished runs: ``view RUN_DIR [OTHER_RUN_DIR ...]``.

Each run comes from its ``trajectory.npz`` (or, without one, its bag); given several, their
robots stand side by side and move in step (the same simulated time). The page has a time
slider, play/pause, the playback speed and a jump to the next support exchange.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import pathlib
import sys
import threading
import time
from typing import TYPE_CHECKING
import zipfile
import zlib

import numpy as np

from iceskate_sim.errors import SimulationError
from iceskate_sim.shutdown import StopRequest, say

if TYPE_CHECKING:  # the page's modules load viser and Pinocchio: only once the runs are read
    from iceskate_viewer.page import RunPage

#: The trajectory columns the view reads.
COLUMNS = ('t', 'q', 'mode', 'side', 'pivot', 'step_index', 'psi_d')
#: Wall time [s] between two frames while playing (at the most).
PLAY_STEP = 1.0 / 30.0


@dataclass(frozen=True)
class Run:
    """A finished run's samples: ``columns`` as in ``trajectory.npz`` (``COLUMNS``)."""

    name: str
    columns: dict[str, np.ndarray]

    @property
    def t(self) -> np.ndarray:
        """Sample times [s]."""
        return self.columns['t']

    def index_at(self, t: float) -> int:
        """The last sample at or before ``t`` [s] (the first before the run starts)."""
        return max(0, int(np.searchsorted(self.t, t, side='right')) - 1)

    def next_exchange(self, t: float) -> float | None:
        """Time [s] of the first support exchange after ``t`` (None: none)."""
        k = self.index_at(t)
        later = np.flatnonzero(self.columns['step_index'][k:] > self.columns['step_index'][k])
        return float(self.t[k + later[0]]) if len(later) else None


def load_run(path: str | pathlib.Path) -> Run:
    """The run in directory ``path``: its ``trajectory.npz``, else its bag.

    :raises SimulationError: naming what is wrong with ``path`` in one sentence.
    """
    run_dir = pathlib.Path(path)
    if not run_dir.is_dir():
        raise SimulationError(f'{run_dir} is not a run directory (no such directory)')
    npz = run_dir / 'trajectory.npz'
    if npz.is_file():
        try:
            with np.load(npz) as data:
                missing = [name for name in COLUMNS if name not in data.files]
                if missing:
                    raise SimulationError(f'{npz} lacks the columns {", ".join(missing)}')
                columns = {name: np.asarray(data[name]) for name in COLUMNS}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
            raise SimulationError(f'{npz} cannot be read: {exc}') from None
    elif (run_dir / 'bag').is_dir():
        from iceskate_analysis.bag_io import read_bag
        bag = read_bag(run_dir / 'bag')
        columns = {'t': bag.t, 'q': bag.q, 'mode': bag.mode, 'side': bag.side,
                   'pivot': bag.pivot, 'step_index': bag.step_index,
                   'psi_d': np.full((bag.n_samples, 3), np.nan)}
    else:
        raise SimulationError(f'{run_dir} holds neither trajectory.npz nor bag/: '
                              'not the output folder of a run')
    if len(columns['t']) == 0:
        raise SimulationError(f'{run_dir} holds no samples')
    return Run(run_dir.resolve().name, columns)


class Replay:
    """The replay page of ``runs`` on ``server``'s ``page``: the controls and their state."""

    def __init__(self, page: RunPage, runs: list[Run]) -> None:
        from iceskate_viewer.pose import ViewFrame
        self._frame_of = ViewFrame.of_columns
        self.page, self.runs = page, runs
        gui = page.server.gui
        end = max(float(run.t[-1]) for run in runs)
        step = float(np.min([np.min(np.diff(run.t)) if len(run.t) > 1 else 1e-3
                             for run in runs]))
        self.slider = gui.add_slider('Time [s]', 0.0, end, step, float(runs[0].t[0]))
        self.playing = gui.add_checkbox('Play', False)
        self.speed = gui.add_number('Speed (x real time)', 1.0, min=0.01, max=100.0, step=0.05)
        self.next_button = gui.add_button('Next support exchange')
        self._lock = threading.Lock()
        self.slider.on_update(lambda _: self.show(self.slider.value))
        self.next_button.on_click(lambda _: self.next_exchange())
        self.show(self.slider.value)

    def show(self, t: float) -> None:
        """Every run at simulated time ``t`` [s]."""
        with self._lock:
            for k, run in enumerate(self.runs):
                self.page.show(k, self._frame_of(run.columns, run.index_at(t)))

    def next_exchange(self) -> None:
        """Jump to the next support exchange of the first run."""
        t = self.runs[0].next_exchange(self.slider.value)
        if t is not None:
            self.slider.value = min(t, self.slider.max)

    def advance(self, wall: float) -> None:
        """Move the slider on by ``wall`` seconds of wall time at the speed, while playing
        (stopping at the end)."""
        if self.playing.value:
            t = self.slider.value + wall * max(0.0, float(self.speed.value))
            if t >= self.slider.max:
                t, self.playing.value = self.slider.max, False
            self.slider.value = t


def main(argv: list[str] | None = None) -> int:
    """``view``: serve the replay page until Ctrl-C."""
    parser = argparse.ArgumentParser(
        prog='view', description='Replay finished runs in 3D in the browser; several runs '
        'stand side by side and move in step.')
    parser.add_argument('runs', nargs='+', metavar='RUN_DIR',
                        help='output folder of a run (its trajectory.npz, or its bag/)')
    parser.add_argument('--host', default='127.0.0.1',
                        help='address to serve on (default 127.0.0.1: this machine only)')
    parser.add_argument('--port', type=int, default=8080,
                        help='port (default 8080; a busy one: the next free one)')
    args = parser.parse_args(argv)
    with StopRequest() as stop:
        from iceskate_viewer.page import (
            RunPage,
            check_host,
            check_port,
            serve,
            stop_server,
            url_of,
        )
        try:
            check_port(args.port, '--port')  # before the runs are read: a second at most
            check_host(args.host)
            runs = [load_run(path) for path in args.runs]
            server = serve(args.host, args.port)
        except SimulationError as exc:
            say(f'view: {exc}')
            return 2
        from iceskate_sim.model.robot import load_robot
        from iceskate_viewer.pose import BodyPose
        try:
            replay = Replay(RunPage(server, BodyPose(load_robot()),
                                    [run.name for run in runs]), runs)
            print(f'view: {url_of(server)} (Ctrl-C to stop)', flush=True)
            last = time.perf_counter()
            while not stop.requested:
                time.sleep(PLAY_STEP)
                now = time.perf_counter()
                replay.advance(now - last)
                last = now
        finally:
            stop_server(server)
    return 0


if __name__ == '__main__':
    sys.exit(main())
