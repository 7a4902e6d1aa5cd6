"""The replay view of finished runs: ``view RUN_DIR [OTHER_RUN_DIR ...]``.

Each run comes from its ``trajectory.npz`` (or, without one, its bag); given several, their
robots stand side by side and move in step (the same simulated time). The page has a time
slider, play/pause, the playback speed and a jump to the next support exchange.

A run of more than ``MAX_FRAMES`` samples is thinned to that many, evenly spaced in time (said
on stderr); ``trajectory.npz`` is read a chunk at a time, so what is held is the frames kept,
whatever the length of the run. What the reading of a bag notes (a bag rebuilt after a killed
run, gaps in its samples) goes to stderr, as ``coupling_analysis`` says it.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
import math
import pathlib
import sys
import threading
import time
from typing import IO, TYPE_CHECKING
import zipfile
import zlib

import numpy as np

from iceskate_native.sample import SAMPLE_COLUMNS
from iceskate_sim.errors import InputRefused, SimulationError
from iceskate_sim.exit_codes import DONE, error_exit
from iceskate_sim.shutdown import StopRequest, say

if TYPE_CHECKING:  # the page's modules load viser and Pinocchio: only once the runs are read
    from iceskate_viewer.page import RunPage

#: The trajectory columns the view reads, and the shape of one sample of each.
SHAPES = {name: SAMPLE_COLUMNS[name].shape()
          for name in ('t', 'q', 'mode', 'side', 'pivot', 'step_index', 'head_target')}
COLUMNS = tuple(SHAPES)
#: Samples of a run the view keeps at the most (a millisecond each of 100 s: more than a
#: slider has positions, and than playback shows at its usual speeds).
MAX_FRAMES = 100_000
#: Bytes of a column of ``trajectory.npz`` read at a time.
CHUNK_BYTES = 4 * 1024 * 1024
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
    """The run in directory ``path``: its ``trajectory.npz``, else its bag (what its reading
    notes said on stderr); more than ``MAX_FRAMES`` samples thinned to them.

    :raises InputRefused: naming what is wrong with ``path`` in one sentence.
    """
    run_dir = pathlib.Path(path)
    if not run_dir.is_dir():
        raise InputRefused(f'{run_dir} is not a run directory (no such directory)')
    npz = run_dir / 'trajectory.npz'
    if npz.is_file():
        try:
            with zipfile.ZipFile(npz) as archive:
                columns = _read_trajectory(archive, npz)
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
            raise InputRefused(f'{npz} cannot be read: {exc}') from None
    elif (run_dir / 'bag').is_dir():
        from iceskate_analysis.bag_io import read_bag
        bag = read_bag(run_dir / 'bag')
        for note in bag.notes:  # e.g. a bag rebuilt after a killed run
            say(f'view: {run_dir}: note: {note}')
        columns = {'t': bag.t, 'q': bag.q, 'mode': bag.mode, 'side': bag.side,
                   'pivot': bag.pivot, 'step_index': bag.step_index,
                   'head_target': np.full((bag.n_samples, 3), np.nan)}
        t = bag.t
        if len(t):
            first, last = _check_times([t], f'bag {bag.path}')
            kept = _frames([t], first, last, len(t), f'bag {bag.path}')
            if kept is not None:
                columns = {name: column[kept] for name, column in columns.items()}
    else:
        raise InputRefused(f'{run_dir} holds neither trajectory.npz nor bag/: '
                           'not the output folder of a run')
    if len(columns['t']) == 0:
        raise InputRefused(f'{run_dir} holds no samples')
    return Run(run_dir.resolve().name, columns)


def _read_trajectory(archive: zipfile.ZipFile, npz: pathlib.Path) -> dict[str, np.ndarray]:
    """The ``COLUMNS`` of the ``trajectory.npz`` ``archive`` (a zip of .npy files, stored or
    deflated: no memory map applies), their times checked, read a chunk at a time and thinned
    to ``MAX_FRAMES`` samples.

    :raises InputRefused: naming ``npz`` and what is wrong with it.
    """
    missing = [name for name in COLUMNS if f'{name}.npy' not in archive.namelist()]
    if missing:
        raise InputRefused(f'{npz} lacks the columns {", ".join(missing)}')
    samples = None
    for name, shape in SHAPES.items():
        with archive.open(f'{name}.npy') as stream:
            found, dtype = _header(stream, npz, name)
        samples = found[0] if name == 't' and found else samples
        if found != (samples, *shape) or dtype.kind not in 'biuf':
            expected = ', '.join(map(str, ('N' if samples is None else samples, *shape)))
            expected += ',' if not shape else ''
            raise InputRefused(f'{npz}: column {name} holds {dtype} of shape {found} where '
                               f'numbers of shape ({expected}) are expected')
    if samples == 0:
        return {name: np.empty((0, *shape)) for name, shape in SHAPES.items()}
    first, last = _check_times(_chunks(archive, 't', npz), str(npz))
    kept = _frames(_chunks(archive, 't', npz), first, last, samples, str(npz))
    columns = {name: _rows(_chunks(archive, name, npz), kept, samples) for name in COLUMNS}
    _check_codes(columns, npz)
    return columns


def _check_codes(columns: dict[str, np.ndarray], npz: pathlib.Path) -> None:
    """Refuse, naming ``npz``, a mode, side or pivot code the view cannot draw."""
    from iceskate_sim.model.modes import MODES
    from iceskate_sim.model.robot import SIDES
    from iceskate_sim.ros.conversions import PIVOT_OF_CODE
    for name, known in (('mode', MODES), ('side', range(len(SIDES))), ('pivot', PIVOT_OF_CODE)):
        unknown = np.setdiff1d(np.unique(columns[name]), list(known))
        if len(unknown):
            raise InputRefused(f'{npz}: column {name} holds codes the view does not know: '
                               f'{", ".join(f"{code:g}" for code in unknown[:5])}')


def _header(stream: IO[bytes], npz: pathlib.Path, name: str) -> tuple[tuple[int, ...],
                                                                       np.dtype]:
    """The shape and dtype of the .npy ``stream`` (column ``name`` of ``npz``), which is left
    at its first value."""
    version = np.lib.format.read_magic(stream)
    if version == (1, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(stream)
    elif version == (2, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(stream)
    else:
        raise InputRefused(f'{npz}: column {name} is in .npy format {version}, not 1.0 or '
                           '2.0')
    if fortran and len(shape) > 1:
        raise InputRefused(f'{npz}: column {name} is stored column by column (Fortran '
                           'order), not sample by sample')
    return tuple(shape), dtype


def _chunks(archive: zipfile.ZipFile, name: str, npz: pathlib.Path) -> Iterator[np.ndarray]:
    """Column ``name``'s samples in order, about ``CHUNK_BYTES`` at a time."""
    with archive.open(f'{name}.npy') as stream:
        shape, dtype = _header(stream, npz, name)
        size = dtype.itemsize * math.prod(shape[1:])
        per_chunk = max(1, CHUNK_BYTES // size)
        for start in range(0, shape[0], per_chunk):
            count = min(per_chunk, shape[0] - start)
            data = stream.read(count * size)
            if len(data) != count * size:
                raise InputRefused(f'{npz}: column {name} ends after '
                                   f'{start + len(data) // size} of its {shape[0]} '
                                   'samples')
            yield np.frombuffer(data, dtype).reshape(count, *shape[1:])


def _check_times(chunks: Iterable[np.ndarray], where: str) -> tuple[float, float]:
    """The first and last of the times ``t`` [s] in ``chunks``.

    :raises InputRefused: naming ``where`` when a time is not finite, is negative or does
        not follow the one before (a slider needs times from 0 s on that increase).
    """
    samples, first, previous = 0, math.nan, -math.inf
    for chunk in chunks:
        t = np.asarray(chunk, dtype=float)
        bad = np.flatnonzero(~np.isfinite(t))
        if len(bad):
            raise InputRefused(f'{where}: time t of sample {samples + bad[0]} is '
                               f'{t[bad[0]]} (not a finite number)')
        if samples == 0:
            first = float(t[0])
            if first < 0.0:
                raise InputRefused(f'{where}: time t starts at {first:g} s (before 0 s)')
        steps = np.diff(t, prepend=previous)
        back = np.flatnonzero(steps <= 0.0)
        if len(back):
            k = back[0]
            before = t[k - 1] if k else previous
            raise InputRefused(f'{where}: time t does not increase: sample {samples + k} '
                               f'is at {t[k]:g} s after {before:g} s')
        samples, previous = samples + len(t), float(t[-1])
    return first, previous


def _frames(chunks: Iterable[np.ndarray], first: float, last: float, samples: int,
            where: str) -> np.ndarray | None:
    """The samples kept of the increasing times ``t`` [s] in ``chunks`` (``first`` to ``last``,
    ``samples`` of them): at most ``MAX_FRAMES``, the first at or after each of as many evenly
    spaced times, said on stderr (None: all of them)."""
    if samples <= MAX_FRAMES:
        return None
    targets = np.linspace(first, last, MAX_FRAMES)
    kept, start, previous = [], 0, -math.inf
    for chunk in chunks:
        t = np.asarray(chunk, dtype=float)
        here = targets[(targets > previous) & (targets <= t[-1])]
        kept.append(start + np.searchsorted(t, here, side='left'))
        start, previous = start + len(t), float(t[-1])
    rows = np.unique(np.concatenate(kept))
    say(f'view: {where}: {samples} samples over {last - first:g} s; showing {len(rows)} of '
        f'them (at most {MAX_FRAMES}), evenly spaced in time')
    return rows


def _rows(chunks: Iterable[np.ndarray], kept: np.ndarray | None, samples: int) -> np.ndarray:
    """The samples ``kept`` (increasing indices; None: all ``samples``) of the column in
    ``chunks``, gathered into one array."""
    out, start, filled = None, 0, 0
    for chunk in chunks:
        if out is None:
            out = np.empty((samples if kept is None else len(kept), *chunk.shape[1:]),
                           chunk.dtype)
        if kept is None:
            rows = chunk
        else:
            lo, hi = np.searchsorted(kept, [start, start + len(chunk)])
            rows = chunk[kept[lo:hi] - start]
        out[filled:filled + len(rows)] = rows
        start, filled = start + len(chunk), filled + len(rows)
    return out


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
            return error_exit('view', exc)
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
    return DONE


if __name__ == '__main__':
    sys.exit(main())
