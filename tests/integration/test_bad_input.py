"""Failures at the graph's boundaries: a dead controller, bad commands, bad parameter files."""

import json
import os
from pathlib import Path
import re
import signal
import subprocess
import sys

import numpy as np
import pytest
import yaml

pytest.importorskip('rclpy')
pytestmark = [pytest.mark.ros, pytest.mark.slow]

from rclpy.duration import Duration  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from iceskate_bringup.graph import command_of, config_file, graph_nodes, stop  # noqa: E402
from iceskate_interfaces.msg import EffortCommand  # noqa: E402
from iceskate_interfaces.srv import StepSimulation  # noqa: E402
from iceskate_sim.model.robot import COORDINATE_NAMES  # noqa: E402
from iceskate_sim.model.stamps import set_stamp  # noqa: E402
from iceskate_sim.ros.node_support import STATE_QOS  # noqa: E402
from oracle.messages import stamp_to_ns  # noqa: E402

TINY = Path(__file__).resolve().parent / 'data' / 'tiny_stand.yaml'
MS = 1_000_000


def test_killed_controller_ends_the_run_naming_it_and_the_bag_reads(
        listener, ros_domain_id, tmp_path, graph_factory):
    # long enough to be running when the listener has found the graph (it is ended earlier)
    graph = graph_factory(tmp_path / 'out', duration=30.0, control_timeout=1.0).start()
    listener.subscribe('/clock', Clock)
    clocks = listener.messages['/clock']
    try:
        listener.spin_until(lambda: clocks and stamp_to_ns(clocks[-1].clock) >= 5 * MS, 60.0,
                            'the run to reach 5 ms')
        os.killpg(graph.processes['gait_manager'].pid, signal.SIGKILL)
        listener.spin_until(lambda: graph.simulator.poll() is not None, 30.0,
                            'the simulator to end the run')
    finally:
        codes = graph.stop()
    log = graph.log('simulator')
    assert codes['simulator'] == 1, log
    # under load the live node may also be late at that instant: it may be named too
    named = re.search(r'no command from node\(s\) (.*) within 1\.0 s', log)
    assert named and "'gait_manager'" in named.group(1).split(', '), log
    failure = json.loads((tmp_path / 'out' / 'metrics.json').read_text())['failure']
    assert 'controller timeout' in failure and 'gait_manager' in failure
    with AnyReader([tmp_path / 'out' / 'bag']) as reader:
        states = [c for c in reader.connections if c.topic == '/joint_states']
        n = sum(1 for _ in reader.messages(connections=states))
    assert n == len(np.load(tmp_path / 'out' / 'trajectory.npz')['t']) >= 5


def test_sigterm_mid_run_closes_the_bag_the_forked_writer_wrote(
        listener, ros_domain_id, tmp_path, graph_factory):
    """The bag writer is forked from the simulator after rclpy started: a SIGTERM to the
    simulator's process group (what run_scene --ros and a terminal's Ctrl-C send) must still
    leave a complete, readable bag and the output files."""
    graph = graph_factory(tmp_path / 'out', duration=30.0).start()
    listener.subscribe('/clock', Clock)
    clocks = listener.messages['/clock']
    try:
        listener.spin_until(lambda: clocks and stamp_to_ns(clocks[-1].clock) >= 150 * MS, 60.0,
                            'the run to pass 150 ms (more than one batch for the writer)')
        os.killpg(graph.simulator.pid, signal.SIGTERM)
        listener.spin_until(lambda: graph.simulator.poll() is not None, 30.0,
                            'the simulator to stop')
    finally:
        graph.stop()
    metrics = json.loads((tmp_path / 'out' / 'metrics.json').read_text())
    assert metrics['failure'].startswith('interrupted by SIGTERM at t=')
    assert metrics['interrupted'] and not metrics['fell']
    n = len(np.load(tmp_path / 'out' / 'trajectory.npz')['t'])
    with AnyReader([tmp_path / 'out' / 'bag']) as reader:
        states = [c for c in reader.connections if c.topic == '/joint_states']
        assert sum(1 for _ in reader.messages(connections=states)) == n >= 150


#: gait_manager's breakdown in tiny_stand (its two sources, zero)
BREAKDOWN = {'source_names': ['posture', 'weight_transfer'], 'source_efforts': [0.0] * 36}


def _command(source: str, ns: int, token: str, **fields) -> EffortCommand:
    msg = EffortCommand(source=source, run_token=token, joint_names=list(COORDINATE_NAMES),
                        effort=[0.0] * 18)
    for key, value in fields.items():
        setattr(msg, key, value)
    set_stamp(msg.header.stamp, ns)
    return msg


def _run_token(out: Path) -> str:
    """The token the launcher gave the nodes of the run in ``out``."""
    return yaml.safe_load((out / 'params' / 'simulator.yaml').read_text())[
        'simulator']['ros__parameters']['run_token']


def _commands_at_3_ms(listener) -> object:
    """A paused run stepped to 3 ms (its /clock there), and a publisher of effort_commands the
    simulator has matched."""
    listener.subscribe('/clock', Clock)
    clocks = listener.messages['/clock']
    publisher = listener.node.create_publisher(EffortCommand, 'effort_commands', STATE_QOS)
    step = StepSimulation.Request(control_periods=3)
    listener.spin_until(lambda: listener.call(StepSimulation, '/simulator/step', step,
                                              timeout=60.0).success, 60.0, 'a step')
    listener.spin_until(lambda: clocks and stamp_to_ns(clocks[-1].clock) == 3 * MS, 30.0,
                        '/clock at 3 ms')
    listener.spin_until(lambda: publisher.get_subscription_count() > 0, 10.0, 'matching')
    return publisher


def test_bad_commands_are_rejected_and_never_reach_the_state(
        graph_run, listener, tmp_path, graph_factory, assert_same_trajectory):
    stats = tmp_path / 'stats.json'
    graph = graph_factory(tmp_path / 'out', start_paused=True, stats_file=str(stats)).start()
    token = _run_token(tmp_path / 'out')
    bad = [_command('gait_manager', 3 * MS, token, effort=[float('nan')] + [0.0] * 17),
           _command('gait_manager', 3 * MS, token, effort=[1.0] * 17),
           _command('gait_manager', 3 * MS, token, joint_names=['y0', 'knee'],
                    effort=[1.0, 1.0]),
           _command('gait_manager', 3 * MS, token, source_names=['posture'],
                    source_efforts=[0.0]),
           _command('gait_manager', 3 * MS, token, source_names=['posture'],
                    source_efforts=[0.0] * 18),
           _command('gait_manager', 1 * MS, token, **BREAKDOWN),
           _command('gait_manager', 1000 * MS, token, **BREAKDOWN),
           _command('posture', 3 * MS, token),
           _command('gait_manager', 3 * MS, '', **BREAKDOWN),
           _command('gait_manager', 3 * MS, 'another run', **BREAKDOWN)]
    try:
        publisher = _commands_at_3_ms(listener)
        for msg in bad:  # one at a time: the simulator's best-effort reader keeps 10
            publisher.publish(msg)
            listener.spin_for(0.05)
        assert publisher.wait_for_all_acked(Duration(seconds=10))
        assert listener.call(Trigger, '/simulator/resume', Trigger.Request()).success
        listener.spin_until(lambda: graph.simulator.poll() is not None, 60.0, 'the end')
    finally:
        codes = graph.stop()
    log = graph.log('simulator')
    assert codes['simulator'] == 0, log
    for reason in ("effort is not finite at ['y0']", 'effort has 17 entries for 18',
                   "unknown joint names ['knee']",
                   'source_efforts has 1 entries for 1 source names x 18 joint names',
                   "'gait_manager' breaks down into sources ['posture']",
                   "stale command of 'gait_manager' stamped 0.001",
                   "'gait_manager' stamped 1.0 s is in the future", "unknown source 'posture'",
                   "a command naming 'gait_manager' is not of this run (its run token differs)"):
        assert 'rejected command: ' in log and reason in log, reason
    assert log.count('is not of this run') == 1, log  # said once, counted every time
    assert json.loads(stats.read_text())['rejected'] == len(bad)
    rejected = json.loads((tmp_path / 'out' / 'metrics.json').read_text())['rejected_commands']
    assert rejected['count'] == len(bad) == sum(rejected['by_reason'].values())
    assert len(rejected['first']) == 5 and "stale command of 'gait_manager' stamped # s " \
        '(simulation at # s)' in rejected['by_reason']
    assert_same_trajectory(tmp_path / 'out' / 'trajectory.npz',
                           graph_run.headless / 'trajectory.npz')


def test_a_second_controller_on_the_domain_steers_nothing_and_is_named(
        graph_run, listener, tmp_path, graph_factory, assert_same_trajectory):
    """A gait_manager started by hand on the run's domain (its shipped parameters, no run
    token) answers the run's states: the simulator names it once, refuses each of its commands
    (one line, every one counted) and the run is the headless one."""
    graph = graph_factory(tmp_path / 'out', start_paused=True).start()
    (spec,) = [s for s in graph.specs if s.executable == 'gait_manager']
    with open(tmp_path / 'intruder.log', 'wb') as log:
        intruder = subprocess.Popen(
            command_of(spec) + ['--ros-args', '--params-file',
                                str(config_file('gait_manager', 'gait_manager'))],
            env=graph.env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        listener.spin_until(lambda: 'publish effort_commands' in graph.log('simulator'), 60.0,
                            'the simulator to see the second gait_manager')
        assert listener.call(Trigger, '/simulator/resume', Trigger.Request()).success
        listener.spin_until(lambda: graph.simulator.poll() is not None, 60.0, 'the end')
    finally:
        codes = graph.stop()
        stop(intruder)
    log = graph.log('simulator')
    assert codes['simulator'] == 0, log
    assert ("1 node(s) named 'gait_manager' publish effort_commands on this ROS domain besides "
            "the run's own; commands without this run's token are refused") in log, log
    assert log.count("a command naming 'gait_manager' is not of this run") == 1, log
    rejected = json.loads((tmp_path / 'out' / 'metrics.json').read_text())['rejected_commands']
    assert rejected['count'] >= 1 and all('not of this run' in r for r in rejected['by_reason'])
    assert_same_trajectory(tmp_path / 'out' / 'trajectory.npz',
                           graph_run.headless / 'trajectory.npz')


@pytest.mark.parametrize('effort', [500.5, 1e300])
def test_a_command_of_the_run_beyond_the_effort_limit_ends_the_run_naming_it(
        listener, tmp_path, graph_factory, effort):
    """A command carrying the run's token (its own controller) whose force exceeds a joint's
    URDF effort limit ends the run at once, naming the joint and the limit (not as a
    controller that stopped answering); the outputs say so."""
    graph = graph_factory(tmp_path / 'out', start_paused=True).start()
    token = _run_token(tmp_path / 'out')
    try:
        publisher = _commands_at_3_ms(listener)
        publisher.publish(_command('gait_manager', 3 * MS, token,
                                   effort=[0.0] * 5 + [effort] + [0.0] * 12, **BREAKDOWN))
        listener.spin_until(lambda: graph.simulator.poll() is not None, 60.0, 'the end')
    finally:
        codes = graph.stop()
    log = graph.log('simulator')
    assert codes['simulator'] == 1, log
    expected = (f"command of 'gait_manager' asks {effort:.6g} N m of q5 at t=0.003000 s, "
                "beyond its effort limit 500 (the URDF's)")
    assert f'rejected command: {expected}; the run ends' in log, log
    metrics = json.loads((tmp_path / 'out' / 'metrics.json').read_text())
    assert metrics['end'] == 'controller_failed' and metrics['failure'] == expected
    assert metrics['sim_time_s'] == pytest.approx(0.003)


@pytest.mark.parametrize('node, parameters, expected', [
    ('simulator', 'control_timeout: -1.0', "parameter 'control_timeout'"),
    ('simulator', 'lockstep: maybe', "parameter 'lockstep'"),
    ('visual_lifting', 'scene_name: stand', "unknown parameter 'scene_name'"),
    ('gait_manager', 'posture: {stiffness: -5.0}', 'posture.stiffness'),
    ('gait_manager', 'enabled: [posture, gait]', 'enabled entries must be one of'),
    ('visual_lifting', 'kp: [1.0, 2.0]', 'kp must have 3 entries'),
])
def test_bad_parameter_file_exits_non_zero_naming_the_parameter(
        tmp_path, ros_env, node, parameters, expected):
    params = tmp_path / 'bad.yaml'
    params.write_text(f'{node}:\n  ros__parameters:\n    {parameters}\n')
    (spec,) = [s for s in graph_nodes(str(TINY), tmp_path / 'out') if s.executable == node] or \
        [s for s in graph_nodes('stand', tmp_path / 'out') if s.executable == node]
    result = subprocess.run(command_of(spec) + ['--ros-args', '--params-file', str(params)],
                            env=ros_env, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result.stderr
    assert expected in result.stderr and result.stderr.startswith(f'{node}: error:'), \
        result.stderr
    assert 'Traceback' not in result.stderr


def test_node_modules_run_without_an_install(tmp_path, ros_env):
    """python -m works too (what the graph falls back to without ros_ws/install)."""
    result = subprocess.run([sys.executable, '-m', 'iceskate_sim.ros.simulator_node', '--ros-args',
                             '-p', 'duration:=-1.0'], env=ros_env, capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 2 and "parameter 'duration'" in result.stderr
