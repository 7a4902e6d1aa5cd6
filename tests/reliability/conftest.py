"""Fault injection: runs as subprocesses, signals, process trees read from /proc.

Every wait has a deadline. A run is started in a session of its own (``start_new_session``), so
a signal to its process group never reaches pytest.
"""

from collections.abc import Iterator
from dataclasses import dataclass
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Any

import pytest

DATA = Path(__file__).resolve().parents[1] / 'integration' / 'data'
TINY = DATA / 'tiny_stand.yaml'  # the stand scene without its push, 1 ms periods
RUNNER = [sys.executable, '-m', 'iceskate_bringup.runner']
FIRST_CHUNK = 1 << 20  # bytes: the bag writer's first chunk reached the disk (the run goes on)


def proc_stat(pid: int) -> tuple[str, int, int, int, int] | None:
    """(state, ppid, pgid, session, start time) of a process from /proc (None: gone)."""
    try:
        text = Path(f'/proc/{pid}/stat').read_text()
    except OSError:
        return None
    fields = text.rsplit(')', 1)[1].split()
    return fields[0], int(fields[1]), int(fields[2]), int(fields[3]), int(fields[19])


def alive(pid: int, start: int | None = None) -> bool:
    """Whether ``pid`` runs (a zombie does not; with ``start``, only that very process)."""
    stat = proc_stat(pid)
    return stat is not None and stat[0] not in 'ZXx' and (start is None or stat[4] == start)


def descendants(pid: int) -> dict[int, int]:
    """pid -> start time of every live process below ``pid`` (children, theirs, ...)."""
    children: dict[int, list[int]] = {}
    starts: dict[int, int] = {}
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            stat = proc_stat(int(entry.name))
            if stat is not None and stat[0] not in 'ZXx':
                children.setdefault(stat[1], []).append(int(entry.name))
                starts[int(entry.name)] = stat[4]
    out, todo = {}, [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            out[child] = starts[child]
            todo.append(child)
    return out


def wait_until(done: Any, timeout: float, what: str, period: float = 0.05) -> None:
    """Poll ``done()`` until it is true; fail the test after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while not done():
        if time.monotonic() > deadline:
            pytest.fail(f'timed out after {timeout} s waiting for {what}')
        time.sleep(period)


def assert_all_gone(processes: dict[int, int], timeout: float = 20.0) -> None:
    """Every process of ``processes`` (pid -> start time) ends within ``timeout`` s."""
    wait_until(lambda: not [p for p, s in processes.items() if alive(p, s)], timeout,
               f'the processes of the run to end (left: '
               f'{[p for p, s in processes.items() if alive(p, s)]})')


@dataclass
class Run:
    """A ``run_scene`` subprocess in a session of its own."""

    process: subprocess.Popen
    out: Path
    seen: dict[int, int]  # pid -> start time of every process of the run seen so far

    @property
    def pid(self) -> int:
        """The run_scene process."""
        return self.process.pid

    def watch(self) -> None:
        """Note the processes below run_scene now (nodes, bag writers)."""
        self.seen.update(descendants(self.pid))

    def wait_running(self, timeout: float = 90.0) -> None:
        """Wait until the bag's first chunk is on disk (the simulation runs)."""
        mcap = self.out / 'bag' / 'bag.mcap'

        def running() -> bool:
            self.watch()
            assert self.process.poll() is None, self.communicate()
            return mcap.is_file() and mcap.stat().st_size >= FIRST_CHUNK
        wait_until(running, timeout, 'the run to write its first chunk')

    def signal(self, signum: int, group: bool) -> None:
        """Send ``signum`` to run_scene's process or to its whole process group."""
        self.watch()
        if group:
            os.killpg(self.pid, signum)
        else:
            os.kill(self.pid, signum)

    def communicate(self, timeout: float = 90.0) -> tuple[int, str, str]:
        """Wait for the end (deadline ``timeout`` s): exit code, stdout, stderr."""
        try:
            stdout, stderr = self.process.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(self.pid, signal.SIGKILL)
            stdout, stderr = self.process.communicate()
            pytest.fail(f'the run did not end within {timeout} s: {stderr[-2000:]}')
        return self.process.returncode, stdout, stderr

    def metrics(self) -> dict[str, Any]:
        """The run's metrics.json."""
        return json.loads((self.out / 'metrics.json').read_text())


@pytest.fixture(scope='session')
def proc() -> Any:
    """The helpers of this folder (tests cannot import conftest): TINY, alive, descendants,
    wait_until, assert_all_gone."""
    from types import SimpleNamespace
    return SimpleNamespace(TINY=TINY, alive=alive, descendants=descendants,
                           wait_until=wait_until, assert_all_gone=assert_all_gone)


@pytest.fixture
def launch(tmp_path: Path, ros_env: dict[str, str]) -> Iterator[Any]:
    """``launch(*args, out=None, prefix=())``: start ``run_scene *args --out OUT`` (own
    session, the test's DDS domain); every run is killed at the end of the test if still up."""
    runs: list[Run] = []

    def start(*args: str, out: Path | None = None, prefix: tuple[str, ...] = ()) -> Run:
        out = out or tmp_path / f'run{len(runs)}'
        env = ros_env | {'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4', 'PYTHONUNBUFFERED': '1'}
        process = subprocess.Popen([*prefix, *RUNNER, *args, '--out', str(out), '--quiet'],
                                   env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                   text=True, start_new_session=True)
        run = Run(process, out, {})
        runs.append(run)
        return run
    try:
        yield start
    finally:
        for run in runs:
            run.watch()
            if run.process.poll() is None:
                os.killpg(run.pid, signal.SIGKILL)
                run.process.communicate()
            for pid, start_time in run.seen.items():
                if alive(pid, start_time):
                    os.kill(pid, signal.SIGKILL)
