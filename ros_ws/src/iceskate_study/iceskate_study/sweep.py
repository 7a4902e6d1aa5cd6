"""Parameter sweeps: ``sweep SPEC --out DIR [--workers N] [--ray ADDRESS|local]``.

Runs every point of a SPEC (``iceskate_study.spec``: a base scene, overrides, axes over any
scene key) headless, on a local process pool (one worker per core by default) or as Ray tasks
(``--ray local`` starts a Ray instance on this machine, ``--ray ADDRESS`` joins a running
cluster), and writes one table, ``DIR/results.parquet`` (``iceskate_study.table``), as runs
finish. Every generated scene is validated before any run starts. A run that falls or fails is
a row with its reason, never the end of the sweep. Running the same SPEC into the same DIR
again resumes: runs already in the table are not done again. SIGINT (Ctrl-C), SIGTERM and
SIGHUP end the sweep cleanly: the runs in flight end between two control periods (and are done
again on resume), the finished rows are in the table, one line says so, and the exit status is
128 + the signal's number. When the SPEC names ``maps``, their heat maps are drawn into
``DIR/maps/`` at the end (``iceskate_study.plot``). Points selected by the SPEC's ``bags`` are
recorded with a bag and all of ``run_scene``'s files in ``DIR/runs/<key>/``.
"""

from __future__ import annotations

import argparse
import contextlib
from dataclasses import dataclass, field
import pathlib
import signal
import sys
import time
from typing import TYPE_CHECKING, Any

# light imports only at the top: main() installs its signal handlers before the heavy ones
from iceskate_sim.errors import SimulationError
from iceskate_sim.shutdown import StopRequest, say
from iceskate_study.errors import StudyError

if TYPE_CHECKING:
    from iceskate_study.spec import Spec

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


def make_executor(workers: int | None, ray: str | None, runs: int) -> Any:
    """The local pool (``ray`` None; ``workers`` or one per CPU, at most ``runs``) or a Ray
    executor (``'local'`` or a cluster address)."""
    from iceskate_study.executors import LocalExecutor, RayExecutor, cpu_count
    if ray is not None:
        return RayExecutor(ray, workers)
    return LocalExecutor(min(workers or cpu_count(), runs))


def run_sweep(spec: Spec, out: pathlib.Path, workers: int | None = None, ray: str | None = None,
              progress: bool = True, stop: StopRequest | None = None,
              maps: bool = True) -> SweepResult:
    """Run every point of ``spec`` not yet in ``out``'s table; write the table (and maps).

    :param workers: processes (local) or runs at once (Ray); None: one per CPU.
    :param ray: None (local processes), ``'local'`` or the address of a Ray cluster.
    :param stop: the signals' stop request (None: one is installed for the call).
    A signal ends the runs in flight and the sweep (``signum`` in the result; no maps); the
    finished rows are in the table.

    :raises StudyError: a bad output folder, a table of another SPEC, Ray not reached.
    """
    from iceskate_sim.run.session import prepare_output
    from iceskate_study.spec import expand
    from iceskate_study.table import ResultTable
    from iceskate_study.worker import Task
    points = expand(spec)
    try:
        prepare_output(out)
    except SimulationError as exc:
        raise StudyError(str(exc)) from None
    table = ResultTable(out, spec, points)
    todo = [p for p in points if p.key not in table.done]
    result = SweepResult(len(points), len(points) - len(todo), table=table.path)
    with contextlib.ExitStack() as stack:
        if stop is None:
            stop = stack.enter_context(StopRequest())
        if todo and not stop.requested:
            executor = make_executor(workers, ray, len(todo))
            stack.callback(executor.close)
            bar = stack.enter_context(_Progress(len(todo), spec.study, progress))
            bar.note(f'{len(todo)} runs on {executor.describe()}'
                     + (f' ({result.resumed} done before)' if result.resumed else ''))
            start = time.perf_counter()
            executor.submit(Task(p.key, p.raw, spec.metrics,
                                 str((out / 'runs' / p.key).resolve()) if p.bag else None)
                            for p in todo)
            interrupted, written = False, time.perf_counter()
            while executor.pending:
                if stop.requested and not interrupted:
                    executor.interrupt(stop.signum or 0)
                    interrupted = True
                for _key, row in executor.completed(POLL):
                    if row is not None:
                        table.add(row)
                        result.ran += 1
                        bar.done(row['status'])
                if table.dirty and time.perf_counter() - written >= WRITE_INTERVAL:
                    table.write()
                    written = time.perf_counter()
            result.wall_time_s = time.perf_counter() - start
        if table.dirty or not table.path.exists():
            table.write()
        for row in table.rows.values():
            result.counts[row['status']] = result.counts.get(row['status'], 0) + 1
        if stop.requested:
            result.signum = stop.signum
            return result
    if maps and spec.maps is not None:
        from iceskate_study.plot import draw_maps
        result.maps = draw_maps(table.path, spec.maps.x, spec.maps.y, spec.maps.metrics,
                                out / 'maps')
    return result


class _Progress:
    """A tqdm bar on stderr: runs done, ETA, runs per minute, falls and failures (silent when
    not enabled or when stderr is gone)."""

    def __init__(self, total: int, study: str, enabled: bool) -> None:
        self._bar: Any = None
        self._counts = {'fell': 0, 'failed': 0}
        self._start = time.perf_counter()
        if enabled:
            from tqdm import tqdm
            self._bar = tqdm(total=total, desc=f'sweep {study}', unit='run', file=sys.stderr,
                             mininterval=0.5, dynamic_ncols=True)

    def __enter__(self) -> _Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            with contextlib.suppress(OSError, ValueError):
                self._bar.close()

    def note(self, text: str) -> None:
        """One line above the bar."""
        if self._bar is not None:
            with contextlib.suppress(OSError, ValueError):
                self._bar.write(text, file=sys.stderr)

    def done(self, status: str) -> None:
        """One more run finished with ``status``."""
        if status in self._counts:
            self._counts[status] += 1
        if self._bar is None:
            return
        minutes = (time.perf_counter() - self._start) / 60.0
        try:
            self._bar.set_postfix_str(
                f'{(self._bar.n + 1) / minutes:.1f} runs/min, fell {self._counts["fell"]}, '
                f'failed {self._counts["failed"]}', refresh=False)
            self._bar.update(1)
        except (OSError, ValueError):
            self._bar = None


def main(argv: list[str] | None = None) -> int:
    """Console entry point.

    Exit status: 0 (every run of the SPEC has its row, whatever its status), 1 (refused, one
    line on stderr saying why), 128 + the signal's number after SIGINT, SIGTERM or SIGHUP.
    """
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
    try:
        if args.workers is not None and args.workers < 1:
            raise StudyError(f'--workers must be >= 1, got {args.workers}')
        from iceskate_study.spec import load_spec
        spec = load_spec(args.spec)
        result = run_sweep(spec, args.out, args.workers, args.ray, progress=not args.quiet,
                           stop=stop, maps=not args.no_maps)
    except StudyError as exc:
        say(f'sweep: error: {exc}')
        return 1
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
    return 0


if __name__ == '__main__':
    sys.exit(main())
