"""Fixtures of the ROS graph integration tests: the graph's processes and a listening test node.

Every process runs on the test's own DDS domain with DDS on loopback, its own ROS_LOG_DIR and
UDPv4 only (a killed process leaves no shared-memory files behind). Every wait has a deadline.
"""

from collections import defaultdict
from collections.abc import Callable, Iterator
from dataclasses import dataclass
import itertools
import json
import os
from pathlib import Path
import subprocess
import time
from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from iceskate_bringup.graph import graph_nodes, ros_environment, start, stop  # noqa: E402
from oracle.messages import stamp_to_ns  # noqa: E402

DATA = Path(__file__).resolve().parent / 'data'
TINY = DATA / 'tiny_stand.yaml'  # 30 control periods of 1 ms
PERIOD_NS = 1_000_000
N_PERIODS = 30
# Module-scoped runs take domain ids from the other half of the range than tests/conftest.py.
_module_domains = itertools.count(os.getpid() % 232 + 116)


def module_domain_id() -> int:
    """A domain id for a module-scoped fixture (1..232)."""
    return 1 + next(_module_domains) % 232


def graph_environment(domain_id: int, log_dir: Path) -> dict[str, str]:
    """Environment of the graph's processes."""
    env = ros_environment(domain_id, log_dir)
    env['FASTDDS_BUILTIN_TRANSPORTS'] = 'UDPv4'
    return env


class Graph:
    """The nodes of one run as processes, each in its own process group."""

    def __init__(self, domain_id: int, out: Path, log_dir: Path, scene: Path = TINY,
                 **simulator_parameters: Any) -> None:
        log_dir.mkdir(parents=True, exist_ok=True)
        self.env = graph_environment(domain_id, log_dir)
        self.log_dir = log_dir
        self.out = out
        self.specs = graph_nodes(str(scene), out, **simulator_parameters)
        self.processes: dict[str, subprocess.Popen] = {}

    def start(self) -> 'Graph':
        """Start every node."""
        for spec in self.specs:
            self.processes[spec.executable] = start(spec, self.env)
        return self

    @property
    def simulator(self) -> subprocess.Popen:
        """The simulator process."""
        return self.processes['simulator']

    def log(self, node: str) -> str:
        """Everything a node printed so far."""
        path = self.log_dir / f'{node}.log'
        return path.read_text(errors='replace') if path.is_file() else ''

    def stop(self) -> dict[str, int]:
        """SIGTERM (then SIGKILL) every node still running; return the exit codes."""
        return {name: stop(p) for name, p in reversed(list(self.processes.items()))}


class Listener:
    """A test node in a private context, with bounded spinning."""

    def __init__(self, domain_id: int) -> None:
        from rclpy.executors import SingleThreadedExecutor
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node('test_listener', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.messages: dict[str, list[Any]] = defaultdict(list)
        self.subscriptions: dict[str, Any] = {}

    def subscribe(self, topic: str, msg_type: type, depth: int = 1000, raw: bool = False,
                  latched: bool = False) -> None:
        """Collect every message of a topic into ``messages[topic]``."""
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                         else DurabilityPolicy.VOLATILE)
        self.subscriptions[topic] = self.node.create_subscription(
            msg_type, topic, self.messages[topic].append, qos, raw=raw)

    def spin_until(self, done: Callable[[], bool], timeout: float, what: str) -> None:
        """Spin until ``done()``; fail the test after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while not done():
            if time.monotonic() > deadline:
                pytest.fail(f'timed out after {timeout} s waiting for {what}')
            self.executor.spin_once(timeout_sec=0.05)

    def spin_until_quiet(self, quiet: float = 0.3, timeout: float = 10.0) -> None:
        """Spin until no message came for ``quiet`` s (the callbacks of what the transport
        already holds are all run, also on a loaded machine), at most ``timeout`` s."""
        deadline = time.monotonic() + timeout
        count, changed = -1, time.monotonic()
        while time.monotonic() < deadline:
            now, seen = time.monotonic(), sum(len(m) for m in self.messages.values())
            if seen != count:
                count, changed = seen, now
            elif now - changed >= quiet:
                return
            self.executor.spin_once(timeout_sec=0.02)

    def spin_for(self, seconds: float) -> None:
        """Process whatever arrives during ``seconds`` (to see that nothing does)."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.02)

    def call(self, srv_type: type, name: str, request: Any, timeout: float = 20.0) -> Any:
        """Call a service; fail the test after ``timeout`` s."""
        client = self.node.create_client(srv_type, name)
        self.spin_until(client.service_is_ready, timeout, f'service {name}')
        future = client.call_async(request)
        self.spin_until(future.done, timeout, f'the response of {name}')
        self.node.destroy_client(client)
        return future.result()

    def close(self) -> None:
        """Destroy the node and shut the context down."""
        self.node.destroy_node()
        self.context.try_shutdown()


@pytest.fixture
def udp_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """This process's DDS participants use UDPv4 like the graph's processes."""
    monkeypatch.setenv('FASTDDS_BUILTIN_TRANSPORTS', 'UDPv4')


@pytest.fixture
def listener(ros_domain_id: int, udp_only: None) -> Iterator[Listener]:
    """A Listener on the test's domain."""
    node = Listener(ros_domain_id)
    try:
        yield node
    finally:
        node.close()


@dataclass
class GraphRun:
    """What the module's run left behind."""

    out: Path
    headless: Path
    messages: dict[str, list[Any]]
    step_response: Any
    clock_while_paused: list[int]
    reset_response: Any
    exit_codes: dict[str, int]
    stats: dict[str, Any]
    graph: Graph


def assert_same_trajectory(a_path: Path, b_path: Path) -> None:
    """Two trajectory.npz files agree to 1e-12 (relative to each column's largest value)."""
    a, b = np.load(a_path), np.load(b_path)
    assert sorted(a.files) == sorted(b.files)
    for key in a.files:
        assert a[key].shape == b[key].shape, key
        scale = max(1.0, float(np.max(np.abs(b[key])))) if b[key].size else 1.0
        error = float(np.max(np.abs(a[key] - b[key]), initial=0.0))
        assert error <= 1e-12 * scale, f'{key}: max difference {error:.3g}'


@pytest.fixture(scope='session')
def graph_run(tmp_path_factory: pytest.TempPathFactory) -> GraphRun:
    """One lockstep run of the three processes, watched by a test node (session-wide)."""
    from geometry_msgs.msg import PoseStamped
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from std_srvs.srv import Trigger

    from iceskate_bringup.runner import run
    from iceskate_bringup.scene import load_scene
    from iceskate_interfaces.msg import EffortCommand, GaitState
    from iceskate_interfaces.srv import StepSimulation
    root = tmp_path_factory.mktemp('graph')
    run(load_scene(TINY), root / 'headless', progress=False)
    domain = module_domain_id()
    saved = os.environ.get('FASTDDS_BUILTIN_TRANSPORTS')
    os.environ['FASTDDS_BUILTIN_TRANSPORTS'] = 'UDPv4'
    listener = Listener(domain)
    graph = Graph(domain, root / 'ros', root / 'log', start_paused=True,
                  stats_file=str(root / 'stats.json'))
    try:
        for topic, kind in (('/clock', Clock), ('/joint_states', JointState),
                            ('/gait_state', GaitState), ('/head_pose', PoseStamped),
                            ('/effort_commands', EffortCommand)):
            listener.subscribe(topic, kind)
        listener.subscribe('/robot_description', String, depth=1, latched=True)
        graph.start()
        step = StepSimulation.Request(control_periods=2)
        response = listener.call(StepSimulation, '/simulator/step', step, timeout=60.0)
        while not response.success:  # the simulator waits for its controllers first
            assert graph.simulator.poll() is None, graph.log('simulator')
            listener.spin_for(0.1)
            response = listener.call(StepSimulation, '/simulator/step', step)
        clocks = listener.messages['/clock']
        listener.spin_until(lambda: clocks and stamp_to_ns(clocks[-1].clock) >= 2 * PERIOD_NS,
                            30.0, '/clock at 2 ms')
        listener.spin_for(0.3)  # paused again: the clock must stay at 2 ms
        while_paused = [stamp_to_ns(c.clock) for c in clocks]
        reset = listener.call(Trigger, '/simulator/reset', Trigger.Request())
        assert listener.call(Trigger, '/simulator/resume', Trigger.Request()).success
        listener.spin_until(lambda: graph.simulator.poll() is not None, 60.0,
                            'the simulator to finish the run')
        listener.spin_until_quiet()  # the last instants' callbacks, however slow the machine
        codes = graph.stop()
    finally:
        graph.stop()
        listener.close()
        if saved is None:
            os.environ.pop('FASTDDS_BUILTIN_TRANSPORTS', None)
        else:
            os.environ['FASTDDS_BUILTIN_TRANSPORTS'] = saved
    assert codes['simulator'] == 0, graph.log('simulator')
    return GraphRun(root / 'ros', root / 'headless', dict(listener.messages), response,
                    while_paused, reset, codes, json.loads((root / 'stats.json').read_text()),
                    graph)


@pytest.fixture(name='assert_same_trajectory')
def assert_same_trajectory_fixture() -> Callable[[Path, Path], None]:
    """The trajectory comparison (1e-12, scaled by each column's largest value)."""
    return assert_same_trajectory


@pytest.fixture
def graph_factory(ros_domain_id: int, tmp_path: Path, udp_only: None
                  ) -> Iterator[Callable[..., Graph]]:
    """``graph_factory(out, **simulator_parameters)``: a Graph on the test's domain (stopped
    at the end of the test)."""
    graphs: list[Graph] = []

    def make(out: Path, scene: Path = TINY, **simulator_parameters: Any) -> Graph:
        graph = Graph(ros_domain_id, out, tmp_path / f'log{len(graphs)}', scene,
                      **simulator_parameters)
        graphs.append(graph)
        return graph
    try:
        yield make
    finally:
        for graph in graphs:
            graph.stop()
