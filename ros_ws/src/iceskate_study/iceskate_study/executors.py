"""Where a sweep's runs go: a local process pool (the default) or Ray tasks on a cluster.

Both take ``Task`` objects and hand back ``(key, row)`` pairs as runs finish (``row`` None for
a run a signal ended), run the same ``iceskate_study.worker.run_task``, and so give the same
rows for the same tasks.

* ``LocalExecutor``: ``concurrent.futures.ProcessPoolExecutor`` of forked workers (one per core
  by default), each warmed up once (``worker.warm_up``: modules and robot model loaded). A
  worker that dies (a crash in native code) breaks the pool: a new one is made and the runs in
  flight are given again; a run that was running in a worker at two such deaths is recorded as
  failed.
* ``RayExecutor``: ``ray.init(address=...)`` joins a running cluster, ``'local'`` starts an
  instance on this machine bound to the loopback address (no dashboard). Ray's usage-statistics
  reporting is switched off (``RAY_USAGE_STATS_ENABLED=0``) unless the environment says
  otherwise. A local instance's processes start with a private ``HOME`` holding an empty
  ``ray_bootstrap_config.yaml``: without that file Ray's head asks the cloud metadata address
  (169.254.169.254) what machine it runs on, even with the reporting off, and nothing may
  leave this machine (the tasks see that ``HOME`` too). Each run is one task of one CPU;
  Ray keeps its worker processes, and with them the loaded model, between tasks.
"""

from __future__ import annotations

from collections.abc import Iterable
import concurrent.futures as cf
import contextlib
import multiprocessing
import os
import pathlib
import signal
import tempfile
from typing import Any

from iceskate_study.errors import StudyError
from iceskate_study.worker import Task, run_marked, run_task, warm_up

#: Deaths of a worker process during the same run before the run is recorded as failed.
MAX_CRASHES = 2


def cpu_count() -> int:
    """The CPUs this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else (
        os.cpu_count() or 1)


def crashed_row(task: Task, failure: str) -> dict[str, Any]:
    """The row of a run whose worker process died."""
    return {'key': task.key, 'status': 'failed', 'failure': failure, 'run_dir': task.run_dir,
            'worker_time_s': None}


class LocalExecutor:
    """Runs on a pool of ``workers`` forked processes of this machine."""

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._marks = tempfile.TemporaryDirectory(prefix='iceskate-sweep-')
        self._pool = self._new_pool()
        self._futures: dict[cf.Future[dict[str, Any] | None], Task] = {}
        self._crashes: dict[str, int] = {}

    def _new_pool(self) -> cf.ProcessPoolExecutor:
        return cf.ProcessPoolExecutor(self.workers, multiprocessing.get_context('fork'),
                                      initializer=warm_up)

    def describe(self) -> str:
        """Where the runs go, in words."""
        return f'{self.workers} local worker process{"es" if self.workers > 1 else ""}'

    @property
    def pending(self) -> int:
        """Runs given and not yet handed back."""
        return len(self._futures)

    def submit(self, tasks: Iterable[Task]) -> None:
        """Queue ``tasks``."""
        for task in tasks:
            self._futures[self._pool.submit(run_marked, task, self._marks.name)] = task

    def completed(self, timeout: float) -> list[tuple[str, dict[str, Any] | None]]:
        """The runs that finished within ``timeout`` s."""
        done, _ = cf.wait(self._futures, timeout, return_when=cf.FIRST_COMPLETED)
        out: list[tuple[str, dict[str, Any] | None]] = []
        broken = ''
        for future in done:
            if future.cancelled():
                out.append((self._futures.pop(future).key, None))
                continue
            try:
                row = future.result()
            except cf.process.BrokenProcessPool as exc:
                broken = str(exc) or type(exc).__name__
                continue
            out.append((self._futures.pop(future).key, row))
        if broken:
            out += self._restart(broken)
        return out

    def _restart(self, reason: str) -> list[tuple[str, dict[str, Any] | None]]:
        """A new pool after a worker died: the runs that were running in a worker then count
        a crash (at MAX_CRASHES they are failed rows), every other one is given again."""
        marks = pathlib.Path(self._marks.name)
        running = {mark.read_text(encoding='ascii') for mark in marks.iterdir()}
        for mark in marks.iterdir():
            mark.unlink()
        rest = list(self._futures.values())
        self._futures.clear()
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = self._new_pool()
        rows: list[tuple[str, dict[str, Any] | None]] = []
        again = []
        for task in rest:
            self._crashes[task.key] = self._crashes.get(task.key, 0) + (task.key in running)
            if self._crashes[task.key] >= MAX_CRASHES:
                rows.append((task.key, crashed_row(
                    task, f'the worker process died while running it, {MAX_CRASHES} times '
                          f'({reason})')))
            else:
                again.append(task)
        self.submit(again)
        return rows

    def interrupt(self, signum: int) -> None:
        """End the runs in flight cleanly (``signum`` to every worker: each ends its run
        between two control periods) and drop the queued ones."""
        for future in list(self._futures):
            if future.cancel():
                self._futures.pop(future)
        for child in multiprocessing.active_children():
            with contextlib.suppress(OSError):
                os.kill(child.pid or 0, signum)

    def close(self) -> None:
        """Stop the workers."""
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._marks.cleanup()


class RayExecutor:
    """Runs as Ray tasks: on a running cluster (``address``) or a local instance
    (``'local'``, ``workers`` CPUs, bound to 127.0.0.1).

    :param workers: runs in flight at once (None: the cluster's CPUs).
    """

    def __init__(self, address: str, workers: int | None) -> None:
        os.environ.setdefault('RAY_USAGE_STATS_ENABLED', '0')
        import ray
        self._ray: Any = ray
        sigterm = signal.getsignal(signal.SIGTERM)  # ray.init installs its own handler
        options: dict[str, Any] = {'include_dashboard': False, 'log_to_driver': False,
                                   'logging_level': 'ERROR'}
        self._home: tempfile.TemporaryDirectory[str] | None = None
        home = os.environ.get('HOME')
        try:
            if address == 'local':
                self._home = tempfile.TemporaryDirectory(prefix='iceskate-ray-home-')
                (pathlib.Path(self._home.name) / 'ray_bootstrap_config.yaml').write_text('{}\n')
                os.environ['HOME'] = self._home.name  # for the processes ray.init starts
                ray.init(num_cpus=workers or cpu_count(), _node_ip_address='127.0.0.1',
                         **options)
            else:
                ray.init(address=address, **options)
        except Exception as exc:  # Ray's errors (a cluster not reached, ...) in one line
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
        self.workers = max(1, min(workers or cpus, cpus))
        self._remote = ray.remote(num_cpus=1)(run_task)
        self._queue: list[Task] = []
        self._refs: dict[Any, Task] = {}

    def describe(self) -> str:
        """Where the runs go, in words."""
        where = 'a local Ray instance' if self.address == 'local' else f'Ray at {self.address}'
        return f'{where}, {self.workers} run{"s" if self.workers > 1 else ""} at once'

    @property
    def pending(self) -> int:
        """Runs given and not yet handed back."""
        return len(self._refs) + len(self._queue)

    def submit(self, tasks: Iterable[Task]) -> None:
        """Queue ``tasks`` (at most ``2 workers`` are Ray tasks at a time)."""
        self._queue.extend(tasks)
        self._feed()

    def _feed(self) -> None:
        while self._queue and len(self._refs) < 2 * self.workers:
            task = self._queue.pop(0)
            self._refs[self._remote.remote(task)] = task

    def completed(self, timeout: float) -> list[tuple[str, dict[str, Any] | None]]:
        """The runs that finished within ``timeout`` s."""
        ray = self._ray
        if not self._refs:
            return []
        ready, _ = ray.wait(list(self._refs), num_returns=1, timeout=timeout)
        if ready:  # and whatever else is ready now
            ready, _ = ray.wait(list(self._refs), num_returns=len(self._refs), timeout=0)
        out: list[tuple[str, dict[str, Any] | None]] = []
        for ref in ready:
            task = self._refs.pop(ref)
            try:
                out.append((task.key, ray.get(ref)))
            except ray.exceptions.TaskCancelledError:
                out.append((task.key, None))
            except ray.exceptions.RayError as exc:  # the worker died (after Ray's retries)
                out.append((task.key, crashed_row(
                    task, f'the Ray task failed: {str(exc).splitlines()[0]}')))
        self._feed()
        return out

    def interrupt(self, signum: int) -> None:
        """Cancel the runs in flight (their workers are stopped) and drop the queued ones."""
        self._queue.clear()
        for ref in self._refs:
            with contextlib.suppress(Exception):
                self._ray.cancel(ref, force=True)

    def close(self) -> None:
        """Leave the cluster (a local instance is stopped)."""
        self._ray.shutdown()
        if self._home is not None:
            self._home.cleanup()
