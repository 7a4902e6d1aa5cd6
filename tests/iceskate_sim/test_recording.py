"""The bag recorder: a background writer process writes the same bag as an in-process one, and
its failures and the run's failures still leave a closed, readable bag; the native loop's
samples are what the oracle records of the same run."""

from dataclasses import replace
from functools import partial
import json
import os
import pathlib

import numpy as np
import pinocchio as pin
import pytest
from rosbags.rosbag2 import Reader

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.runner import run
from iceskate_bringup.scene import load_scene
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.modes import MULTIPLIER_NAMES
from iceskate_sim.model.robot import PIVOTS, SIDES, load_robot
from iceskate_sim.model.stamps import seconds_to_ns
from iceskate_sim.recording.bag import BagRecorder
from iceskate_sim.recording.messages import RECORDED_TOPICS, Events, SampleMessages
from iceskate_sim.run.session import Session
from oracle.commands import stack_commands
from oracle.simulator import reference_samples

#: a fast-stepping skate gait (test data): many events in a short window
FAST_SKATE = pathlib.Path(__file__).resolve().parents[1] / 'data' / 'fast_skate.yaml'

BLOCK = 100  # periods per native block
PERIODS = 2 * BLOCK + 17  # two full blocks and a partial one


@pytest.fixture(scope='module')
def blocks(native_blocks) -> list[tuple[dict, Events]]:
    """The first periods of the stand scene (push, visual lifting, posture stabiliser) on the
    native loop, in blocks of ``BLOCK``, each with its latest events."""
    scene = replace(load_scene('stand'), duration=PERIODS * 1e-3, record_bag=False)
    got, events, _ = native_blocks(scene, BLOCK)
    assert [len(b['t']) for b in got] == [BLOCK, BLOCK, 17]
    return [(b, Events.of(b['last_event'], events)) for b in got]


def _messages(bag: pathlib.Path) -> list[tuple[str, int, bytes]]:
    with Reader(bag) as reader:
        return [(c.topic, t, bytes(data)) for c, t, data in reader.messages()]


def _record(path: pathlib.Path, blocks: list[tuple[dict, Events]],
            background: bool) -> BagRecorder:
    urdf = load_robot().urdf_path.read_text(encoding='utf-8')
    with BagRecorder(path, {'scene': 'stand'}, urdf, background=background) as recorder:
        for block, events in blocks:
            recorder.write_block(block, events)
    return recorder


def test_background_writer_writes_the_same_messages(tmp_path, blocks):
    _record(tmp_path / 'inline', blocks, background=False)
    recorder = _record(tmp_path / 'background', blocks, background=True)
    inline, background = _messages(tmp_path / 'inline'), _messages(tmp_path / 'background')
    assert recorder.count == PERIODS
    assert len(background) == 1 + 6 * PERIODS  # the URDF, then 6 topics per sample
    assert background == inline


def test_the_bag_holds_each_samples_messages_in_order(tmp_path, blocks):
    """After the URDF, each sample's six messages in ``RECORDED_TOPICS`` order, stamped with
    its time, the bytes ``SampleMessages`` encodes (the bag adds nothing to them)."""
    recorder = _record(tmp_path / 'bag', blocks, background=False)
    got = _messages(tmp_path / 'bag')
    urdf = load_robot().urdf_path.read_text(encoding='utf-8')
    assert got[0] == ('/robot_description', 0, recorder.messages.description(urdf))
    t = np.concatenate([b['t'] for b, _ in blocks])
    assert [(topic, stamp) for topic, stamp, _ in got[1:]] == [
        (topic, seconds_to_ns(float(time))) for time in t for topic in RECORDED_TOPICS]
    encoder = SampleMessages(recorder.messages.typestore, recorder.messages.tf_frames)
    expected = []
    for block, events in blocks:
        encoded = encoder.encode(block, events)
        expected += [encoded[topic][k] for k in range(len(block['t']))
                     for topic in RECORDED_TOPICS]
    assert [data for _, _, data in got[1:]] == expected


def test_the_bag_says_the_urdf_is_latched_and_replay_offers_it_so(tmp_path, blocks):
    """/robot_description is recorded with the QoS the simulator offers it with (transient
    local, reliable, depth 1), which ``ros2 bag play`` and Foxglove replay; the live and
    replayed publishers use that profile."""
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
    from rosbags.interfaces import QosDurability, QosReliability

    from iceskate_sim.ros.node_support import LATCHED_QOS
    _record(tmp_path / 'bag', blocks[:1], background=False)
    with Reader(tmp_path / 'bag') as reader:
        offered = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    (urdf,) = offered.pop('/robot_description')
    assert (urdf.durability, urdf.reliability, urdf.depth) == (
        QosDurability.TRANSIENT_LOCAL, QosReliability.RELIABLE, 1)
    assert offered and not any(offered.values())  # the others: as a plain reliable topic
    assert (LATCHED_QOS.durability, LATCHED_QOS.reliability, LATCHED_QOS.depth) == (
        DurabilityPolicy.TRANSIENT_LOCAL, ReliabilityPolicy.RELIABLE, 1)


def test_the_background_writer_runs_at_idle_priority(tmp_path, blocks):
    """The writer takes only the CPU time the run leaves (SCHED_IDLE), whatever the parent's
    scheduling; the parent's stays as it was."""
    before = os.sched_getscheduler(0)
    urdf = load_robot().urdf_path.read_text(encoding='utf-8')
    with BagRecorder(tmp_path / 'bag', {'scene': 'stand'}, urdf,
                     background=True) as recorder:
        recorder.write_block(*blocks[0])
        assert os.sched_getscheduler(recorder._process.pid) == os.SCHED_IDLE
    assert os.sched_getscheduler(0) == before


def test_a_failing_background_writer_raises_and_leaves_a_closed_bag(tmp_path, blocks,
                                                                    monkeypatch):
    def broken(self, block, events, topics=RECORDED_TOPICS):
        raise OSError('disk full')
    monkeypatch.setattr(SampleMessages, 'encode', broken)  # forked along
    with pytest.raises(SimulationError, match='bag writer .* failed: OSError: disk full'):
        _record(tmp_path / 'bag', blocks, background=True)
    assert [topic for topic, _, _ in _messages(tmp_path / 'bag')] == ['/robot_description']


def test_a_closed_recorder_refuses_blocks_and_an_existing_bag_is_refused(tmp_path, blocks):
    recorder = _record(tmp_path / 'bag', blocks[:1], background=False)
    with pytest.raises(SimulationError, match='is closed'):
        recorder.write_block(*blocks[1])
    recorder.close()  # idempotent
    assert len(_messages(tmp_path / 'bag')) == 1 + 6 * BLOCK
    with pytest.raises(SimulationError, match='already exists'):
        _record(tmp_path / 'bag', blocks, background=False)


def test_a_native_run_that_fails_leaves_a_readable_bag_of_the_periods_before(tmp_path):
    # a residual bound below the projection's round-off: the walk's first constrained period
    # fails inside a native block of periods
    scene = load_scene('walk')
    scene = replace(scene, duration=1.5,
                    simulator=replace(scene.simulator, residual_bound=1e-18))
    with pytest.raises(SimulationError, match='constraint residual'):
        run(scene, tmp_path, progress=False)
    clock = [t for topic, t, _ in _messages(tmp_path / 'bag') if topic == '/clock']
    metrics = json.loads((tmp_path / 'metrics.json').read_text())
    # every period of the bag's (each 4th) before the failing one (which ended at sim_time_s)
    periods = range(0, round(metrics['sim_time_s'] * 1000) - 1, scene.bag_every)
    assert scene.bag_every == 4 and 0 < len(clock) == len(periods) < 1500 / 4
    assert clock == [k * 1_000_000 for k in periods]


def test_the_native_block_holds_what_the_oracle_samples_record(native_blocks):
    """The native loop's block columns of 0.6 s of skating are what the oracle's
    ``reference_samples`` record of the same run: the same modes, sides, pivots, steps,
    sources and latest transitions, values equal to the round-off the two formulations of
    eq. (7) grow over 0.6 s."""
    scene = replace(load_scene('skate'), duration=0.6, record_bag=False)
    got, events, _ = native_blocks(scene, 250)
    b = {key: np.concatenate([block[key] for block in got])
         for key in ('t', 'q', 'v', 'qdd', 'passive', 'multipliers', 'support_normal',
                     'support_friction', 'mode', 'side', 'pivot', 'step_index',
                     'head_position', 'head_orientation', 'last_event', 'present')}
    sources = got[0]['sources']
    assert all(block['sources'] == sources for block in got)
    efforts = {name: np.concatenate([block['efforts'][i] for block in got])
               for i, name in enumerate(sources)}
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    samples = reference_samples(scene, session.robot, partial(stack_commands, stack), 600)
    assert len(b['t']) == len(samples) == 600
    close = {'rtol': 1e-6, 'atol': 1e-6}
    for k, sample in enumerate(samples):
        state, result = sample.state, sample.result
        assert b['t'][k] == pytest.approx(state.t, abs=1e-12)
        assert (b['mode'][k], b['side'][k], b['pivot'][k], b['step_index'][k]) == (
            state.mode.number, SIDES.index(state.contact.side),
            1 + PIVOTS.index(state.contact.pivot) if state.mode.q1_active else 0,
            state.step_index), k
        np.testing.assert_allclose(b['q'][k], state.q, **close)
        np.testing.assert_allclose(b['v'][k], state.v, **close)
        np.testing.assert_allclose(b['qdd'][k], result.qdd, **close)
        np.testing.assert_allclose(b['passive'][k], result.passive, **close)
        np.testing.assert_allclose(b['multipliers'][k], result.multipliers, **close)
        np.testing.assert_allclose([b['support_normal'][k], b['support_friction'][k]],
                                   [result.support_normal, result.support_friction], **close)
        acting = {name for i, name in enumerate(sources) if int(b['present'][k]) >> i & 1}
        assert acting == set(sample.efforts), k
        for name in sources:
            np.testing.assert_allclose(efforts[name][k], sample.efforts.get(name, np.zeros(18)),
                                       **close)
        np.testing.assert_allclose(b['head_position'][k], sample.head_position, **close)
        rotation = pin.Quaternion(*np.roll(b['head_orientation'][k], 1)).toRotationMatrix()
        np.testing.assert_allclose(rotation, sample.head_rotation, **close)
        index = int(b['last_event'][k])
        last = sample.last_transition
        assert (index >= 0) == (last is not None), k
        if last is not None:
            native = events[index]
            assert (native.cause, native.event, native.from_mode, native.to_mode) == (
                last.cause, last.event, last.from_mode, last.to_mode), k
            assert native.t == pytest.approx(last.t, abs=1e-6)
    assert len(set(b['mode'].tolist())) >= 2 and (b['last_event'] >= 0).any()
    assert len(MULTIPLIER_NAMES) == b['multipliers'].shape[1]


def test_a_run_at_a_record_rate_keeps_every_nth_sample_and_analyses(tmp_path):
    """``record.rate`` 250 at the 1 kHz control rate: the trajectory and the bag hold the
    samples of every 4th period, the same values as the full run's, and eq. (11) still closes
    on them (each sample carries its own accelerations and efforts)."""
    from iceskate_analysis.bag_io import read_bag
    from iceskate_analysis.coupling import decompose
    from iceskate_bringup.scene import parse_scene
    raw = {**load_scene(FAST_SKATE).raw, 'duration': 0.6}
    full = tmp_path / 'full'
    run(parse_scene({**raw, 'record': {'bag': False}}), full, progress=False)
    every4 = tmp_path / 'every4'
    metrics = run(parse_scene({**raw, 'record': {'rate': 250}}), every4, progress=False)
    assert metrics['failure'] is None and metrics['steps'] > 0
    a, b = np.load(full / 'trajectory.npz'), np.load(every4 / 'trajectory.npz')
    assert len(a['t']) == 600 and len(b['t']) == 150
    for key in a.files:
        assert np.array_equal(b[key], a[key][::4], equal_nan=True), key
    clock = [t for topic, t, _ in _messages(every4 / 'bag') if topic == '/clock']
    assert clock == [4_000_000 * k for k in range(150)]
    d = decompose(read_bag(every4 / 'bag'), (11,))[11]
    assert d.valid.all() and d.residual_rel.max() <= 1e-9


def test_the_bag_holds_every_nth_sample_of_the_full_rate_bag(tmp_path):
    """``record.bag_rate`` (250 Hz by default) thins the bag alone: the trajectory keeps
    every period, and each message of the bag is the full-rate bag's at the same stamp."""
    from iceskate_analysis.bag_io import read_bag
    from iceskate_analysis.coupling import decompose
    from iceskate_bringup.scene import parse_scene
    raw = {**load_scene(FAST_SKATE).raw, 'duration': 0.6}
    thinned, full = tmp_path / 'thinned', tmp_path / 'full'
    run(parse_scene(raw), thinned, progress=False)
    run(parse_scene({**raw, 'record': {'bag_rate': None}}), full, progress=False)
    a, b = np.load(full / 'trajectory.npz'), np.load(thinned / 'trajectory.npz')
    assert len(b['t']) == 600 and all(np.array_equal(a[k], b[k], equal_nan=True)
                                      for k in a.files)
    every = {topic: [(t, data) for name, t, data in _messages(full / 'bag') if name == topic]
             for topic in ('/clock', '/joint_states', '/head_pose', '/gait_state',
                           '/joint_dynamics')}
    got = _messages(thinned / 'bag')
    assert [(t, data) for topic, t, data in got if topic == '/clock'] == every['/clock'][::4]
    for topic in ('/joint_states', '/head_pose', '/gait_state', '/joint_dynamics'):
        assert [(t, d) for name, t, d in got if name == topic] == every[topic][::4], topic
    tf = [t for topic, t, _ in got if topic == '/tf']
    assert tf == [k * 1_000_000 for k in range(0, 600, 8)]  # every 2nd: 125 Hz
    d = decompose(read_bag(thinned / 'bag'), (11,))[11]
    assert d.valid.all() and d.residual_rel.max() <= 1e-9


def _short_session(tmp_path: pathlib.Path, periods: int = 120) -> Session:
    scene = replace(load_scene('stand'), duration=periods * 1e-3)
    session = Session(scene, tmp_path, tmp_path / 'bag')
    stack = ControlStack(scene, session.robot, session.observation())
    while not session.done:
        session.run_periods(stack, 50)
    return session


def test_the_bag_is_closed_whatever_the_written_hook_does(tmp_path):
    """``finish`` calls ``written`` (the runner draws the summary there) before it waits for
    the bag writer; an exception there still leaves a closed bag with every period."""
    session = _short_session(tmp_path)

    def written() -> None:
        assert (tmp_path / 'metrics.json').is_file() and (tmp_path / 'trajectory.npz').is_file()
        raise RuntimeError('drawing failed')
    with pytest.raises(RuntimeError, match='drawing failed'):
        session.finish(written=written)
    clock = [t for topic, t, _ in _messages(tmp_path / 'bag') if topic == '/clock']
    assert clock == [k * 1_000_000 for k in range(0, 120, 4)]  # the bag's 250 Hz


def test_a_bag_that_fails_to_close_is_the_runs_failure(tmp_path, monkeypatch):
    """Closing the bag fails after the outputs were written: the metrics are written again
    saying so, and ``written`` runs again (the summary shows it)."""
    session = _short_session(tmp_path)

    real_close = BagRecorder.close

    def close(recorder: BagRecorder) -> None:
        real_close(recorder)  # the writer process ends as it would
        raise SimulationError('bag writer for bag failed: OSError: disk full')
    monkeypatch.setattr(BagRecorder, 'close', close)
    calls = []
    metrics = session.finish(written=lambda: calls.append(
        json.loads((tmp_path / 'metrics.json').read_text())['failure']))
    assert calls == [None, 'bag writer for bag failed: OSError: disk full']
    assert metrics['failure'] == calls[-1]
    assert json.loads((tmp_path / 'metrics.json').read_text())['failure'] == calls[-1]


def test_a_spilling_trajectory_holds_what_one_in_memory_holds(tmp_path, blocks):
    """Past its memory budget a Trajectory moves its samples to files (a long run's memory stays
    flat): the columns, a source that starts late included, equal the in-memory ones, for
    blocks of any size, and the files go with the Trajectory."""
    from iceskate_sim.run.metrics import Trajectory
    kept, spilled = Trajectory(), Trajectory(tmp_path, spill_bytes=20_000)
    rows = {key: np.concatenate([b[key] for b, _ in blocks])
            for key in ('t', 'q', 'v', 'mode', 'side', 'zmp_y')}
    sources = blocks[0][0]['sources']
    efforts = {name: np.concatenate([b['efforts'][i] for b, _ in blocks])
               for i, name in enumerate(sources)}
    edges = [0, 1, 2, 9, 40, 41, 120, 150, 151, 190, PERIODS]  # blocks of 1 to 79 samples
    for start, stop in zip(edges[:-1], edges[1:], strict=True):
        columns = {key: value[start:stop] for key, value in rows.items()}
        block_efforts = {name: value[start:stop] for name, value in efforts.items()}
        if start == 150:  # a source that acts once, after samples were spilled
            block_efforts['late'] = np.full((1, 18), 0.5)
        for trajectory in (kept, spilled):
            trajectory.extend(columns, block_efforts)
    assert spilled._spilled > 0 and spilled._held <= 20_000
    a, b = kept.arrays(), spilled.arrays()
    assert a.keys() == b.keys() == {*rows, *(f'tau_{name}' for name in [*sources, 'late'])}
    assert len(kept) == len(spilled) == PERIODS
    for key in a:
        assert np.array_equal(a[key], b[key], equal_nan=True), key
    for key, value in rows.items():
        assert np.array_equal(b[key], value, equal_nan=True), key
    acted = np.flatnonzero(a['tau_late'].any(axis=1))  # at sample 150 only: 0 elsewhere
    assert acted.tolist() == [150] and np.all(a['tau_late'][150] == 0.5)
    folder = spilled._spill_dir
    assert folder.parent == tmp_path and any(folder.iterdir())
    del spilled, trajectory, b
    import gc
    gc.collect()
    assert not folder.exists()


def test_a_spill_that_meets_a_full_disk_leaves_every_sample_readable(tmp_path, blocks,
                                                                      monkeypatch):
    """The disk fills up while the samples move to files, after some columns were appended:
    the move is undone (the files as before, the samples kept in memory) and raised as an
    ``io_error``; the columns still hold every sample, and a later move completes it."""
    from iceskate_sim.errors import SimulationError
    from iceskate_sim.run.metrics import Trajectory
    kept, spilled = Trajectory(), Trajectory(tmp_path, spill_bytes=20_000)
    rows = {key: np.concatenate([b[key] for b, _ in blocks]) for key in ('t', 'q', 'v')}
    write = Trajectory._write
    calls = {'n': 0, 'full': False}

    def filling(self, key, block):
        calls['n'] += 1
        if calls['full'] and calls['n'] % 3 == 0:
            raise OSError(28, 'No space left on device')
        write(self, key, block)
    monkeypatch.setattr(Trajectory, '_write', filling)
    failed = 0
    for start in range(0, PERIODS, 20):
        columns = {key: value[start:start + 20] for key, value in rows.items()}
        calls['full'] = 60 <= start < 160
        kept.extend(columns, {})
        try:
            spilled.extend(columns, {})
        except SimulationError as exc:
            assert exc.end == 'io_error' and 'No space left on device' in str(exc)
            failed += 1
    assert failed >= 1 and spilled._spilled > 0
    a, b = kept.arrays(), spilled.arrays()
    for key in a:
        assert np.array_equal(a[key], b[key], equal_nan=True), key
