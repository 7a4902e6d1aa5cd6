"""Soak: back-to-back runs through the ROS graph, a random node SIGKILLed at a random moment in
every other one. No run gets stuck, no process of a run outlives it, every bag is readable."""

import contextlib
import os
from pathlib import Path
import random
import signal
import threading
import time

import pytest

pytest.importorskip('rclpy')
pytestmark = [pytest.mark.ros, pytest.mark.slow]

from rosbags.highlevel import AnyReader  # noqa: E402

from iceskate_sim.errors import SimulationError  # noqa: E402

TINY = Path(__file__).resolve().parents[1] / 'integration' / 'data' / 'tiny_stand.yaml'
RUNS = 20
DURATION = 2.0  # s simulated per run
DEADLINE = 60.0  # s of wall time a run may take (run_graph's timeout)
NODES = ('simulator', 'visual_lifting', 'gait_manager')


def _run_processes(out: Path) -> dict[int, tuple[int, str]]:
    """pid -> (start time, node) of the live processes of the run writing into ``out`` (the
    nodes name their parameter file there; a simulator's bag writer shares its command line)."""
    found = {}
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            cmdline = (entry / 'cmdline').read_bytes().decode(errors='replace')
            stat = (entry / 'stat').read_text().rsplit(')', 1)[1].split()
        except OSError:
            continue
        if stat[0] in 'ZXx':
            continue
        for node in NODES:
            if str(out / 'params' / f'{node}.yaml') in cmdline:
                found[int(entry.name)] = (int(stat[19]), node)
    return found


class _Killer(threading.Thread):
    """Watches a run's processes; SIGKILLs ``victim`` ``delay`` s after the bag appears."""

    def __init__(self, out: Path, victim: str | None, delay: float) -> None:
        super().__init__(daemon=True)
        self.out, self.victim, self.delay = out, victim, delay
        self.seen: dict[int, tuple[int, str]] = {}
        self.killed: int | None = None
        self.done = threading.Event()

    def run(self) -> None:
        bag_seen_at = None
        while not self.done.is_set():
            self.seen.update(_run_processes(self.out))
            if bag_seen_at is None and (self.out / 'bag' / 'bag.mcap').is_file():
                bag_seen_at = time.monotonic()
            if (self.victim and self.killed is None and bag_seen_at is not None
                    and time.monotonic() - bag_seen_at > self.delay):
                # the oldest process of the node: the node itself, not a bag writer it forked
                pids = sorted((s, p) for p, (s, n) in self.seen.items() if n == self.victim)
                if pids:
                    self.killed = pids[0][1]
                    with contextlib.suppress(ProcessLookupError):  # the run may be over
                        os.kill(self.killed, signal.SIGKILL)
            time.sleep(0.02)


def _alive(pid: int, start: int) -> bool:
    try:
        stat = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    except OSError:
        return False
    return stat[0] not in 'ZXx' and int(stat[19]) == start


@pytest.mark.timeout(900)
def test_back_to_back_ros_runs_with_random_nodes_killed(tmp_path, ros_domain_id, monkeypatch):
    from iceskate_bringup import graph
    monkeypatch.setenv('FASTDDS_BUILTIN_TRANSPORTS', 'UDPv4')
    monkeypatch.setattr(graph, '_write_summary', lambda out: None)  # not what is soaked here
    rng = random.Random(20261124)
    outcomes = []
    for k in range(RUNS):
        out = tmp_path / f'run{k:02d}'
        victim = rng.choice(NODES) if k % 2 else None
        killer = _Killer(out, victim, rng.uniform(0.0, 3.0))
        killer.start()
        started = time.monotonic()
        try:
            metrics = graph.run_graph(str(TINY), out, duration=DURATION,
                                      domain_id=ros_domain_id, timeout=DEADLINE,
                                      control_timeout=1.0, startup_timeout=30.0)
            outcome = f'complete at t={metrics["sim_time_s"]:.3f} s'
        except SimulationError as exc:
            outcome = str(exc).splitlines()[0]
        finally:
            killer.done.set()
            killer.join(timeout=10.0)
        elapsed = time.monotonic() - started
        outcomes.append((k, victim, killer.killed, round(elapsed, 1), outcome))
        assert elapsed < DEADLINE + 30.0, outcomes[-1]  # no stuck run
        if victim is None:
            assert outcome.startswith('complete at t=2.000'), outcomes[-1]
        assert killer.seen, outcomes[-1]
        deadline = time.monotonic() + 20.0
        while left := [p for p, (s, _n) in killer.seen.items() if _alive(p, s)]:
            assert time.monotonic() < deadline, (outcomes[-1], left)  # no leaked process
            time.sleep(0.05)
        with AnyReader([out / 'bag']) as reader:  # every bag has its metadata and index
            assert reader.message_count >= 1, outcomes[-1]  # at least /robot_description
    print('\n'.join(map(str, outcomes)))
