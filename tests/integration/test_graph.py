"""The three nodes as separate processes run a short scene in lockstep.

One module-scoped run (started paused, stepped 2 periods through ~/step, resumed) is watched by
a test node; the tests then check the live topics and stamps, the services, the bag (rosbags and
the independent mcap reader), the equality with the headless runner, and that a second run (in
one process) records the same message payloads.
"""

import hashlib
import json
import os
from pathlib import Path
import time

import numpy as np
import pytest
import yaml

pytest.importorskip('rclpy')
pytestmark = [pytest.mark.ros, pytest.mark.slow]

from rosbags.highlevel import AnyReader  # noqa: E402

from iceskate_bringup import graph  # noqa: E402
from iceskate_bringup.graph import (  # noqa: E402
    graph_nodes,
    realtime_scheduling,
    ros_environment,
    run_graph,
)
from iceskate_bringup.scene import load_scene, scene_sources  # noqa: E402
from oracle.messages import stamp_to_ns  # noqa: E402

TESTS = Path(__file__).resolve().parent
TINY = TESTS / 'data' / 'tiny_stand.yaml'
PERIOD_NS = 1_000_000
N_PERIODS = 30
BAG_TOPICS = {'/clock', '/joint_states', '/head_pose', '/gait_state', '/joint_dynamics', '/tf',
              '/robot_description'}


def test_run_leaves_the_headless_files_and_exits_cleanly(graph_run):
    # the nodes started by hand: the run's parameter files, and no picture (run_graph draws it)
    assert {p.name for p in graph_run.out.iterdir()} == (
        {p.name for p in graph_run.headless.iterdir()} - {'summary.png'} | {'params'})
    assert set(graph_run.exit_codes.values()) == {0}, graph_run.exit_codes
    assert graph_run.stats['periods'] == N_PERIODS and graph_run.stats['rejected'] == 0


def test_trajectory_equals_the_headless_runners(graph_run, assert_same_trajectory):
    assert_same_trajectory(graph_run.out / 'trajectory.npz',
                               graph_run.headless / 'trajectory.npz')
    ros = json.loads((graph_run.out / 'metrics.json').read_text())
    headless = json.loads((graph_run.headless / 'metrics.json').read_text())
    assert ros.keys() == headless.keys()
    for key in ('scene', 'sim_time_s', 'steps', 'fell', 'failure', 'transitions', 'sources',
                'mode_time_fraction', 'physics_steps'):
        assert ros[key] == headless[key], key


def test_step_and_pause_services(graph_run):
    assert graph_run.step_response.success
    assert stamp_to_ns(graph_run.step_response.sim_time) == 2 * PERIOD_NS
    assert max(graph_run.clock_while_paused) == 2 * PERIOD_NS
    assert not graph_run.reset_response.success
    assert 'refused while the run is recorded' in graph_run.reset_response.message


def test_free_running_mode_is_paced_to_wall_time(tmp_path, ros_domain_id):
    # the pace counts from the start, the wall time from the first period: slow enough that
    # the first tick's delay (up to ~0.1 s) is small against the run (3 s)
    metrics = run_graph(str(TINY), tmp_path / 'free', single_process=True,
                        domain_id=ros_domain_id, timeout=120.0, lockstep=False,
                        pace=0.01)
    assert metrics['failure'] is None
    assert metrics['sim_time_s'] == pytest.approx(N_PERIODS * 1e-3, abs=1e-9)
    assert metrics['wall_time_s'] >= 0.9 * metrics['sim_time_s'] / 0.01


def test_three_processes_take_an_empty_string_parameter(tmp_path, ros_domain_id):
    # the simulator's command line: '-p record_bag:=' does not parse, '-p record_bag:=""' does
    metrics = run_graph(str(TINY), tmp_path / 'no_bag', domain_id=ros_domain_id, timeout=120.0,
                        record_bag='', duration=0.01)
    assert metrics['failure'] is None
    assert metrics['sim_time_s'] == pytest.approx(0.01, abs=1e-9)
    assert not (tmp_path / 'no_bag' / 'bag').exists()
    assert (tmp_path / 'no_bag' / 'trajectory.npz').exists()


def test_live_topics_carry_every_instant_with_matching_stamps(graph_run):
    m = graph_run.messages
    stamps = [stamp_to_ns(msg.header.stamp) for msg in m['/joint_states']]
    # the first instants may go out before the test node is matched (the simulator waits for
    # the controllers, not for it); a state the controllers have not answered within 0.25 s is
    # published again (same stamp); otherwise every instant once
    assert stamps[0] <= N_PERIODS // 2 * PERIOD_NS and stamps == sorted(stamps)
    assert sorted(set(stamps)) == list(range(stamps[0], N_PERIODS * PERIOD_NS, PERIOD_NS))
    assert [stamp_to_ns(c.clock) for c in m['/clock']][-len(stamps):] == stamps
    for topic in ('/gait_state', '/head_pose'):
        assert [stamp_to_ns(msg.header.stamp) for msg in m[topic]][-len(stamps):] == stamps
    assert {msg.header.frame_id for msg in m['/head_pose']} == {'world'}
    sources = set(scene_sources(load_scene(TINY)))  # one command per node
    answers: dict[int, set[str]] = {}
    for cmd in m['/effort_commands']:
        answers.setdefault(stamp_to_ns(cmd.header.stamp), set()).add(cmd.source)
    assert set(answers) <= set(range(0, N_PERIODS * PERIOD_NS, PERIOD_NS))
    # the test node may be matched with a controller late (discovery timing, not lockstep:
    # the simulator's own completeness is checked by periods == N and the trajectory), but
    # from the first command it hears of a source on it hears that source at every instant
    # (the run may even end before the test node hears any controller at all)
    heard = {source for got in answers.values() for source in got}
    assert heard <= sources, (heard, sources)
    for source in heard:
        first = min(ns for ns, got in answers.items() if source in got)
        missing = [ns for ns in stamps if ns >= first and source not in answers.get(ns, ())]
        assert not missing, f'{source}: no command heard at {missing}'
    assert '<robot' in m['/robot_description'][0].data
    trajectory = np.load(graph_run.out / 'trajectory.npz')
    for msg in m['/joint_states']:
        k = int(round(stamp_to_ns(msg.header.stamp) / PERIOD_NS))
        np.testing.assert_array_equal(msg.position, trajectory['q'][k])


def _bag_payloads(bag: Path) -> tuple[dict[str, int], str]:
    digest = hashlib.sha256()
    counts: dict[str, int] = {}
    with AnyReader([bag]) as reader:
        for conn, timestamp, raw in reader.messages():
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
            digest.update(conn.topic.encode() + timestamp.to_bytes(8, 'little') + bytes(raw))
    return counts, digest.hexdigest()


def test_bag_reads_back_with_rosbags_and_mcap(graph_run):
    bag = graph_run.out / 'bag'
    counts, _ = _bag_payloads(bag)
    assert set(counts) == BAG_TOPICS
    assert counts['/robot_description'] == 1
    assert {counts[t] for t in BAG_TOPICS - {'/robot_description', '/tf'}} == {N_PERIODS}
    assert counts['/tf'] == -(-N_PERIODS // 10)  # at 100 Hz, from the first sample
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == '/gait_state']
        stamps = [stamp_to_ns(reader.deserialize(raw, c.msgtype).header.stamp)
                  for c, _, raw in reader.messages(connections=conns)]
        assert stamps == list(range(0, N_PERIODS * PERIOD_NS, PERIOD_NS))
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['storage_identifier'] == 'mcap'
    assert json.loads(info['custom_data']['scene_parameters'])['scene'] == 'tiny_stand'
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    (path,) = bag.glob('*.mcap')
    decoded: dict[str, int] = {}
    with path.open('rb') as f:
        for _, channel, _, msg in make_reader(f, decoder_factories=[DecoderFactory()]) \
                .iter_decoded_messages():
            decoded[channel.topic] = decoded.get(channel.topic, 0) + 1
            if channel.topic == '/joint_dynamics':
                assert len(msg.acceleration) == 18 and msg.source_names[0] == 'visual_lifting'
    assert decoded == counts


def test_two_runs_record_identical_payloads(graph_run, tmp_path, ros_domain_id,
                                            assert_same_trajectory):
    out = tmp_path / 'again'
    run_graph(str(TINY), out, single_process=True, domain_id=ros_domain_id, timeout=120.0)
    assert _bag_payloads(out / 'bag') == _bag_payloads(graph_run.out / 'bag')
    assert_same_trajectory(out / 'trajectory.npz', graph_run.out / 'trajectory.npz')


def test_run_scene_ros_cli_runs_three_processes(graph_run, tmp_path, ros_env,
                                                 assert_same_trajectory):
    import subprocess
    import sys
    out = tmp_path / 'cli'
    result = subprocess.run(
        [sys.executable, '-m', 'iceskate_bringup.runner', str(TINY), '--ros', '--out', str(out)],
        env=ros_env | {'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4'}, capture_output=True, text=True,
        timeout=120)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)['failure'] is None
    assert {p.name for p in out.iterdir()} == (
        {p.name for p in graph_run.headless.iterdir()} | {'params'})
    assert sorted(p.name for p in (out / 'params').iterdir()) == [
        'gait_manager.yaml', 'scene.yaml', 'simulator.yaml', 'visual_lifting.yaml']
    assert_same_trajectory(out / 'trajectory.npz', graph_run.headless / 'trajectory.npz')


def test_run_scene_ros_refuses_an_out_holding_a_run_before_starting_nodes(tmp_path, ros_env):
    import subprocess
    import sys
    out = tmp_path / 'cli'
    (out / 'bag').mkdir(parents=True)  # the bag may not be overwritten
    result = subprocess.run(
        [sys.executable, '-m', 'iceskate_bringup.runner', str(TINY), '--ros', '--out', str(out)],
        env=ros_env | {'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4'}, capture_output=True, text=True,
        timeout=120)
    assert result.returncode == 2
    assert result.stderr.startswith(f'run_scene: error: output directory {out} already holds a '
                                    f'recorded run: {out / "bag"} already exists'), result.stderr
    assert 'graph: domain' not in result.stderr  # no node was started


def test_rt_priority_starts_the_nodes_under_sched_fifo_with_the_same_trajectory(
        needs_fifo, graph_run, tmp_path, ros_domain_id, monkeypatch, assert_same_trajectory):
    started = []

    def spy(spec, env, lock=None, start=graph.start):
        started.append((spec.executable, os.sched_getscheduler(0), os.sched_getparam(0)))
        return start(spec, env, lock)
    monkeypatch.setattr(graph, 'start', spy)
    before = (os.sched_getscheduler(0), os.sched_getparam(0))
    out = tmp_path / 'fifo'
    metrics = run_graph(str(TINY), out, domain_id=ros_domain_id, timeout=120.0, rt_priority=10)
    assert metrics['failure'] is None
    assert sorted(name for name, *_ in started) == sorted(
        ['simulator', *scene_sources(load_scene(TINY))])
    assert all(policy == os.SCHED_FIFO and param.sched_priority == 10
               for _, policy, param in started)
    assert (os.sched_getscheduler(0), os.sched_getparam(0)) == before  # this thread: restored
    assert_same_trajectory(out / 'trajectory.npz', graph_run.headless / 'trajectory.npz')


def test_every_thread_of_a_node_started_under_rt_priority_is_sched_fifo(needs_fifo, tmp_path,
                                                                       ros_domain_id):
    env = ros_environment(ros_domain_id, tmp_path)
    spec = next(s for s in graph_nodes(str(TINY), tmp_path / 'out') if s.executable != 'simulator')
    with realtime_scheduling(10):
        process = graph.start(spec, env)  # a controller: up until stopped, waiting for states
    try:
        deadline = time.monotonic() + 60.0
        while True:
            assert process.poll() is None, graph.stop(process)
            tasks = list(Path(f'/proc/{process.pid}/task').iterdir())
            if any((t / 'comm').read_text().startswith('dds.') for t in tasks):
                break
            assert time.monotonic() < deadline, 'no transport threads within 60 s'
            time.sleep(0.1)
        # /proc/<tid>/stat after the command name: field 40 rt_priority, 41 policy
        fields = {t.name: (t / 'stat').read_text().rsplit(')', 1)[1].split() for t in tasks}
        assert len(fields) > 3
        assert {(int(f[37]), int(f[38])) for f in fields.values()} == {(10, os.SCHED_FIFO)}
    finally:
        graph.stop(process)  # maybe still starting up: its exit code is not this test's


def test_the_whole_skate_scene_through_the_graph_equals_the_headless_run(
        tmp_path, ros_domain_id, assert_same_trajectory):
    """15 s, 40 support exchanges, every law and source: the three processes give the headless
    trajectory to 1e-12 and the same events (the controllers see the same stamped times)."""
    from iceskate_bringup.runner import run
    headless = run(load_scene('skate'), tmp_path / 'headless', progress=False)
    metrics = run_graph('skate', tmp_path / 'ros', domain_id=ros_domain_id, timeout=600.0)
    assert metrics['failure'] is None and metrics['steps'] == headless['steps'] >= 12
    assert_same_trajectory(tmp_path / 'ros' / 'trajectory.npz',
                           tmp_path / 'headless' / 'trajectory.npz')
    assert (json.loads((tmp_path / 'ros' / 'events.json').read_text())
            == json.loads((tmp_path / 'headless' / 'events.json').read_text()))
