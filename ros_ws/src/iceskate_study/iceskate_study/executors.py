"""Where a sweep's runs go: a local process pool (the default) or Ray tasks on a cluster. Both run
``iceskate_study.worker.run_task`` on the same ``Task`` objects, so they give the same rows;
docs/usage.md ("Executors") says how each handles a dying worker, signals and the network.
"""

from __future__ import annotations

import abc
from collections import deque
from collections.abc import Iterable, Iterator
import concurrent.futures as cf
import contextlib
import itertools
import multiprocessing
import os
import pathlib
import signal
import tempfile
from typing import Any

from iceskate_sim.shutdown import say
from iceskate_study.errors import StudyError
from iceskate_study.network import loopback_only
from iceskate_study.worker import Task, run_marked, run_task, warm_up

#: The row of a run in the results table.
Row = dict[str, Any]
#: Deaths of a worker process during the same run before the run is recorded as failed.
MAX_CRASHES = 2


def cpu_count() -> int:
    """The CPUs this process may run on."""
    return len(os.sched_getaffinity(0))


def crashed_row(task: Task, failure: str) -> Row:
    """The row of a run whose worker process died."""
    return {'key': task.key, 'status': 'failed', 'failure': failure, 'run_dir': task.run_dir,
            'worker_time_s': None}


class _Executor(abc.ABC):
    """Runs in flight as futures, at most two per worker at a time; the next ones taken as
    they finish from those given back to be run again (``_queue``), then from those given
    (``_given``, an iterable read no further than that)."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._queue: deque[Task] = deque()
        self._given: Iterator[Task] = iter(())
        self._futures: dict[cf.Future[Row | None], Task] = {}
        #: why the runs left cannot run here any more (None: they can); they have no row, so
        #: the next call runs them
        self.lost: str | None = None

    @abc.abstractmethod
    def _start(self, task: Task) -> cf.Future[Row | None]:
        """Start ``task``: its future row."""

    @abc.abstractmethod
    def _failed(self, failed: list[tuple[Task, BaseException]]) -> list[Row]:
        """The rows of the runs whose future raised (at least one)."""

    @property
    def pending(self) -> bool:
        """Whether runs given are not handed back yet (after ``submit`` and ``completed``,
        which start the next ones: none in flight means none left)."""
        return bool(self._queue or self._futures)

    def submit(self, tasks: Iterable[Task]) -> None:
        """Run ``tasks``, read as runs finish."""
        self._given = itertools.chain(self._given, tasks)
        self._feed()

    def _drop(self) -> None:
        """Drop the runs not started."""
        self._queue.clear()
        self._given = iter(())

    def _feed(self) -> None:
        while len(self._futures) < 2 * self.workers:
            task = self._queue.popleft() if self._queue else next(self._given, None)
            if task is None:
                return
            self._futures[self._start(task)] = task

    def completed(self, timeout: float) -> list[Row]:
        """The rows of the runs that finished within ``timeout`` s (a run a signal ended, or
        cancelled, has none)."""
        done, _ = cf.wait(self._futures, timeout, return_when=cf.FIRST_COMPLETED)
        rows: list[Row] = []
        failed: list[tuple[Task, BaseException]] = []
        for future in [f for f in self._futures if f in done]:  # in the order given
            task = self._futures.pop(future)
            if future.cancelled():
                continue
            if (error := future.exception()) is not None:
                failed.append((task, error))
            elif (row := future.result()) is not None:
                rows.append(row)
        rows += self._failed(failed) if failed else []
        self._feed()
        return rows


class LocalExecutor(_Executor):
    """Runs on a pool of ``workers`` forked processes of this machine."""

    def __init__(self, workers: int) -> None:
        super().__init__(workers)
        self._marks = tempfile.TemporaryDirectory(prefix='iceskate-sweep-')
        self._pool = self._new_pool()
        self._crashes: dict[str, int] = {}

    def _new_pool(self) -> cf.ProcessPoolExecutor:
        return cf.ProcessPoolExecutor(self.workers, multiprocessing.get_context('fork'),
                                      initializer=warm_up)

    def describe(self) -> str:
        """Where the runs go, in words."""
        return f'{self.workers} local worker process{"es" if self.workers > 1 else ""}'

    def _start(self, task: Task) -> cf.Future[Row | None]:
        return self._pool.submit(run_marked, task, self._marks.name)

    def _failed(self, failed: list[tuple[Task, BaseException]]) -> list[Row]:
        """A worker died (the pool is broken): a new pool; the runs that were running in a
        worker then count a crash (failed rows at MAX_CRASHES), the others are queued again."""
        for _task, error in failed:
            if not isinstance(error, cf.process.BrokenProcessPool):
                raise error
        reason = str(failed[0][1]) or type(failed[0][1]).__name__
        running = set()
        for mark in pathlib.Path(self._marks.name).iterdir():
            running.add(mark.read_text(encoding='ascii'))
            mark.unlink()
        rest = [task for task, _ in failed] + list(self._futures.values())
        self._futures.clear()
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = self._new_pool()
        rows: list[Row] = []
        again = []
        for task in rest:
            self._crashes[task.key] = self._crashes.get(task.key, 0) + (task.key in running)
            if self._crashes[task.key] >= MAX_CRASHES:
                rows.append(crashed_row(task, f'the worker process died while running it, '
                                              f'{MAX_CRASHES} times ({reason})'))
            else:
                again.append(task)
        self._queue.extendleft(reversed(again))
        return rows

    def interrupt(self, signum: int) -> None:
        """End the runs in flight cleanly (``signum`` to every worker: each ends its run
        between two control periods) and drop the ones not started."""
        self._drop()
        for future in self._futures:
            future.cancel()
        for child in multiprocessing.active_children():
            with contextlib.suppress(OSError):
                os.kill(child.pid or 0, signum)

    def close(self) -> None:
        """Stop the workers."""
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._marks.cleanup()


class RayExecutor(_Executor):
    """Runs as Ray tasks: on a running cluster (``address``) or a local instance
    (``'local'``, ``workers`` CPUs, node address 127.0.0.1, started inside a network namespace
    of loopback alone, ``network.loopback_only``, where that is permitted).

    :param workers: runs in flight at once (None: the cluster's CPUs).
    """

    def __init__(self, address: str, workers: int | None) -> None:
        os.environ.setdefault('RAY_USAGE_STATS_ENABLED', '0')
        import ray
        self._ray: Any = ray
        sigterm = signal.getsignal(signal.SIGTERM)  # ray.init installs its own handler
        self._home: tempfile.TemporaryDirectory[str] | None = None
        self._network = contextlib.ExitStack()
        home = os.environ.get('HOME')
        try:
            if address == 'local':  # its home and session files private (0700), removed after
                refused = self._network.enter_context(loopback_only())
                if refused is not None:
                    say('sweep: note: the local Ray instance listens on every interface while '
                        f'the sweep runs (a network of loopback alone was refused: {refused})')
                self._home = tempfile.TemporaryDirectory(prefix='iceskate-ray-',
                                                         ignore_cleanup_errors=True)
                (pathlib.Path(self._home.name) / 'ray_bootstrap_config.yaml').write_text('{}\n')
                os.environ['HOME'] = self._home.name  # for the processes ray.init starts
            ray.init(**({'num_cpus': workers or cpu_count(), '_node_ip_address': '127.0.0.1',
                         '_temp_dir': self._home.name}
                        if address == 'local' else {'address': address}),
                     include_dashboard=False, log_to_driver=False, logging_level='ERROR')
        except Exception as exc:  # Ray's errors (a cluster not reached, ...) in one line
            self._network.close()
            raise StudyError(f'cannot start Ray at {address!r}: '
                             f'{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}'
                             ) from None
        finally:
            if home is not None:
                os.environ['HOME'] = home
            if sigterm is not None:
                signal.signal(signal.SIGTERM, sigterm)
        self.address = address
        cpus = int(ray.cluster_resources().get('CPU', 1))
        super().__init__(max(1, min(workers or cpus, cpus)))
        self._remote = ray.remote(num_cpus=1)(run_task)
        #: the object ref of each run in flight, by its future
        self._refs: dict[cf.Future[Row | None], Any] = {}

    def describe(self) -> str:
        """Where the runs go, in words."""
        where = 'a local Ray instance' if self.address == 'local' else f'Ray at {self.address}'
        return f'{where}, {self.workers} run{"s" if self.workers > 1 else ""} at once'

    def _start(self, task: Task) -> cf.Future[Row | None]:
        self._refs = {f: ref for f, ref in self._refs.items() if f in self._futures}
        ref = self._remote.remote(task)
        future = ref.future()
        self._refs[future] = ref
        return future

    def _failed(self, failed: list[tuple[Task, BaseException]]) -> list[Row]:
        """A cancelled run has no row; a run whose task raised, or whose worker died each
        time Ray tried it, is a failed row; any other loss (the node's raylet died, the object
        store lost the result, ...) is Ray's, not the run's: no row for it or for any run not
        finished, and ``lost`` says why (the next call runs them)."""
        errors = self._ray.exceptions
        rows = []
        for task, error in failed:
            if isinstance(error, errors.TaskCancelledError):
                continue
            if isinstance(error, (errors.RayTaskError, errors.WorkerCrashedError)):
                rows.append(crashed_row(task, f'the Ray task failed: '
                                              f'{str(error).splitlines()[0]}'))
            elif self.lost is None:
                self.lost = (f'Ray lost a run ({type(error).__name__}: '
                             f'{(str(error).splitlines() or [""])[0]})')
        if self.lost is not None:  # what is left would be lost the same way
            self._drop()
            for future in self._futures:
                future.cancel()
            self._futures.clear()
        return rows

    def interrupt(self, signum: int) -> None:
        """Cancel the runs in flight (their workers are stopped) and drop the ones not
        started."""
        self._drop()
        for future in self._futures:
            with contextlib.suppress(Exception):
                self._ray.cancel(self._refs[future], force=True)

    def close(self) -> None:
        """Leave the cluster (a local instance is stopped)."""
        try:
            self._ray.shutdown()
        finally:
            self._network.close()  # the sweep's thread back in its network namespace
            if self._home is not None:
                self._home.cleanup()
