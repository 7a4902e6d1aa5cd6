"""Parameter sweeps: ``sweep SPEC --out DIR [--workers N] [--ray ADDRESS|local]``.

Every run of a SPEC, headless, on local worker processes or Ray tasks, into one resumable table
``DIR/results.parquet``, then the SPEC's heat maps into ``DIR/maps/`` (docs/usage.md).
"""

from __future__ import annotations

import argparse
from collections import Counter
import contextlib
from dataclasses import dataclass, field
import io
import os
import pathlib
import signal
import sys
import time
from typing import TYPE_CHECKING

# light imports only at the top: main() installs its signal handlers before the heavy ones
from iceskate_sim.errors import RunInterrupted, SimulationError
from iceskate_sim.exit_codes import DONE, error_exit
from iceskate_sim.progress import ProgressBar
from iceskate_sim.shutdown import StopRequest, say
from iceskate_study.errors import StudyError, StudyRefused

if TYPE_CHECKING:
    from collections.abc import Iterator

    from iceskate_study.spec import Point, Points, Spec
    from iceskate_study.table import ResultTable
    from iceskate_study.worker import Task

#: Seconds between two writes of the table while runs finish.
WRITE_INTERVAL = 1.0
#: Seconds a wait for finished runs lasts before the loop looks at signals again.
POLL = 0.25


@dataclass
class SweepResult:
    """What a sweep did.

    :ivar total: runs the SPEC makes. :ivar resumed: runs already in the table at the start.
    :ivar ran: runs finished by this sweep. :ivar counts: rows by status (whole table).
    :ivar wall_time_s: the sweep's time from the first run given [s].
    :ivar table: the results table. :ivar maps: heat maps drawn.
    :ivar signum: the signal that ended the sweep early (None: it ran to its end).
    """

    total: int
    resumed: int
    ran: int = 0
    counts: dict[str, int] = field(default_factory=dict)
    wall_time_s: float = 0.0
    table: pathlib.Path | None = None
    maps: list[pathlib.Path] = field(default_factory=list)
    signum: int | None = None


def run_sweep(spec: Spec, out: pathlib.Path, workers: int | None = None, ray: str | None = None,
              progress: bool = True, stop: StopRequest | None = None,
              maps: bool = True) -> SweepResult:
    """Run every point of ``spec`` not yet in ``out``'s table; write the table (and maps).

    :param workers: processes (local) or runs at once (Ray); None: one per CPU.
    :param ray: None (local processes), ``'local'`` or the address of a Ray cluster.
    :param stop: the signals' stop request (None: one is installed for the call); a signal ends
        the runs in flight and the sweep (``signum`` in the result; no maps).
    :raises StudyRefused: a bad output folder, a table of another SPEC.
    :raises StudyError: Ray not reached, runs Ray lost.
    :raises RunInterrupted: a signal before the first run was given (the table untouched).
    """
    from iceskate_sim.run.session import prepare_output, release_output
    from iceskate_study.spec import expand
    from iceskate_study.table import RESULTS, ResultTable
    with contextlib.ExitStack() as signals:
        if stop is None:
            stop = signals.enter_context(StopRequest())
        points = expand(spec, stop)
        try:
            # the entries a sweep of its own makes before its table (a first sweep cut short)
            prepare_output(out, resumes=RESULTS,
                           made=('runs', RAY_MESSAGES, f'.{RESULTS}.partial'))
        except SimulationError as exc:
            raise StudyRefused(str(exc)) from None
        try:
            table = ResultTable(out, spec, points, stop)
            result = SweepResult(len(points), len(table.done), table=table.path)
            _run(points, table, result, out, workers, ray, progress, stop)
        finally:
            release_output(out)
    if maps and spec.maps is not None and result.signum is None:
        from iceskate_study.plot import draw_maps
        result.maps = draw_maps(table.path, spec.maps.x, spec.maps.y, spec.maps.metrics,
                                out / 'maps')
    return result


def _run(points: Points, table: ResultTable, result: SweepResult, out: pathlib.Path,
         workers: int | None, ray: str | None, progress: bool, stop: StopRequest) -> None:
    """Run the runs of ``points`` that ``table`` has no row of, given to the executor a few at
    a time (as many as it keeps in flight), into ``table`` and ``result``."""
    from iceskate_study.worker import Task
    spec, todo = points.spec, len(points) - len(table.done)
    with contextlib.ExitStack() as stack:
        lost: str | None = None  # why the runs left could not run (Ray lost them)
        if todo and not stop.requested:
            from iceskate_study.executors import LocalExecutor, RayExecutor, cpu_count
            executor = (RayExecutor(ray, workers) if ray is not None
                        else LocalExecutor(min(workers or cpu_count(), todo)))
            stack.callback(executor.close)
            bar = stack.enter_context(ProgressBar(todo, f'sweep {spec.study}', 'run', progress))
            bar.note(f'{todo} runs on {executor.describe()}'
                     + (f' ({result.resumed} done before)' if result.resumed else ''))
            start = time.perf_counter()
            given: dict[str, Point] = {}  # the runs the executor was given, by key

            def tasks() -> Iterator[Task]:
                for p in points.remaining(table.done):
                    given[p.key] = p
                    yield Task(p.key, p.raw, spec.metrics,
                               str((out / 'runs' / p.key).resolve()) if p.bag else None)

            executor.submit(tasks())
            interrupted, written, statuses = False, time.perf_counter(), Counter()
            while executor.pending:
                if stop.requested and not interrupted:
                    executor.interrupt(stop.signum or 0)
                    interrupted = True
                for row in executor.completed(POLL):
                    table.add(given.pop(row['key']), row)
                    result.ran += 1
                    statuses[row['status']] += 1
                    minutes = (time.perf_counter() - start) / 60.0
                    bar.update(1, f'{result.ran / minutes:.1f} runs/min, fell '
                                  f'{statuses["fell"]}, failed {statuses["failed"]}')
                if table.dirty and time.perf_counter() - written >= WRITE_INTERVAL:
                    table.write()
                    written = time.perf_counter()
            result.wall_time_s = time.perf_counter() - start
            lost = executor.lost
        if table.dirty or not table.path.exists():
            table.write()
        if lost is not None and not stop.requested:
            left = len(points) - len(table.rows)
            raise StudyError(f'{lost}; {left} runs have no row yet: the same command runs them')
        result.counts = dict(Counter(row['status'] for row in table.rows.values()))
        if stop.requested:
            result.signum = stop.signum


#: The file of DIR that receives what Ray's driver prints (a sweep on Ray only, if any).
RAY_MESSAGES = 'ray_messages.log'


class _LaterFile(io.TextIOBase):
    """A text sink that creates ``path`` (appending) at the first write; a write it cannot
    make is dropped (never the sweep's failure)."""

    def __init__(self, path: pathlib.Path) -> None:
        self.path = path
        self.written = False
        self._file: io.TextIOBase | None = None

    def writable(self) -> bool:
        """A sink."""
        return True

    def write(self, text: str) -> int:
        """Append ``text`` to the file (created now the first time)."""
        with contextlib.suppress(OSError, ValueError):  # ValueError: closed meanwhile
            if self._file is None:
                self._file = self.path.open('a', encoding='utf-8')
            self._file.write(text)
            self._file.flush()
            self.written = True
        return len(text)

    def close(self) -> None:
        """Close the file, if it was made."""
        if self._file is not None:
            self._file.close()
        super().close()


def main(argv: list[str] | None = None) -> int:
    """Console entry point: exit 0 (every run of the SPEC has its row, whatever its status),
    2 (refused before any run) or 1 (Ray not reached, runs lost), with one line on stderr,
    128 + the signal's number (SIGINT, SIGTERM, SIGHUP) (``iceskate_sim.exit_codes``)."""
    with StopRequest() as stop:  # first of all: a signal never leaves the table half-written
        return _main(argv, stop)


def _main(argv: list[str] | None, stop: StopRequest) -> int:
    parser = argparse.ArgumentParser(prog='sweep', description=__doc__.split('\n\n')[0])
    parser.add_argument('spec', help='SPEC file (YAML), or a shipped study name (e.g. arm_swing)')
    parser.add_argument('--out', type=pathlib.Path, required=True,
                        help='output directory (results.parquet, maps/, runs/); the same '
                             'SPEC into the same directory resumes')
    parser.add_argument('--workers', type=int, metavar='N',
                        help='worker processes (local) or runs at once (Ray); default: one '
                             'per CPU')
    parser.add_argument('--ray', metavar='ADDRESS|local',
                        help="run as Ray tasks: 'local' starts a Ray instance on this machine, "
                             'an address (e.g. 10.0.0.5:6379) joins a running cluster')
    parser.add_argument('--no-maps', action='store_true', help="do not draw the SPEC's maps")
    parser.add_argument('--quiet', action='store_true', help='no progress bar')
    args = parser.parse_args(argv)
    if argv is None and args.ray == 'local':  # the command itself, without root: started again
        from iceskate_study.network import run_in_own_namespaces  # where Ray can have a
        run_in_own_namespaces('iceskate_study.sweep', sys.argv[1:])  # loopback of its own
    ray_messages = _LaterFile(args.out / RAY_MESSAGES)
    try:
        if args.workers is not None and args.workers < 1:
            raise StudyRefused(f'--workers must be >= 1, got {args.workers}')
        from iceskate_study.spec import load_spec
        spec = load_spec(args.spec, stop)
        if args.ray == 'local':  # one machine: Ray's node address is loopback, not probed
            os.environ.setdefault('RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER', '0')  # via 8.8.8.8
        # Ray's driver prints the cluster's messages (a raylet's death: its last log lines)
        # on stdout, which the sweep does not use otherwise: into a file of DIR instead
        with (contextlib.closing(ray_messages), contextlib.redirect_stdout(ray_messages)
              if args.ray else contextlib.nullcontext()):
            result = run_sweep(spec, args.out, args.workers, args.ray,
                               progress=not args.quiet, stop=stop, maps=not args.no_maps)
    except StudyError as exc:
        messages = (f" (Ray's messages: {ray_messages.path})"
                    if args.ray and ray_messages.written else '')
        return error_exit('sweep', exc, f'{exc}{messages}')
    except RunInterrupted as exc:  # while the SPEC's scenes or the table were read
        say(f'sweep: interrupted by {signal.Signals(exc.signum).name} before any run started; '
            'the same command resumes')
        return exc.exit_code
    if result.signum is not None:
        say(f'sweep: interrupted by {signal.Signals(result.signum).name}: {result.ran} runs '
            f'finished now, {sum(result.counts.values())} of {result.total} in {result.table}; '
            'the same command resumes')
        return 128 + result.signum
    counts = ', '.join(f'{result.counts.get(s, 0)} {s}' for s in ('ok', 'fell', 'failed'))
    rate = (f', {60.0 * result.ran / result.wall_time_s:.1f} runs/min'
            if result.wall_time_s > 0 else '')
    say(f'sweep {spec.study}: {result.total} runs ({result.ran} done now in '
        f'{result.wall_time_s:.1f} s{rate}, {result.resumed} before): {counts}')
    say(f'table: {result.table}')
    if result.maps:
        say(f'maps: {", ".join(str(p) for p in result.maps)}')
    return DONE


if __name__ == '__main__':
    sys.exit(main())
