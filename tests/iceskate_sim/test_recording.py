"""The bag recorder: a background writer process writes the same bag as an in-process one, and
its failures and the run's failures still leave a closed, readable bag."""

from dataclasses import replace
import json
import os
import pathlib

import numpy as np
import pytest
from rosbags.rosbag2 import Reader

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.runner import run
from iceskate_bringup.scene import load_scene
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.robot import load_robot
from iceskate_sim.recording import bag as recording
from iceskate_sim.recording.bag import BATCH, BagRecorder, Sample
from iceskate_sim.run.session import Session
from oracle.simulator import reference_samples

#: a fast-stepping skate gait (test data): many events in a short window
FAST_SKATE = pathlib.Path(__file__).resolve().parents[1] / 'data' / 'fast_skate.yaml'

PERIODS = 2 * BATCH + 17  # two full batches and a partial one


@pytest.fixture(scope='module')
def samples() -> list[Sample]:
    """The first periods of the stand scene (push, visual lifting, posture stabiliser), on the
    oracle."""
    scene = replace(load_scene('stand'), duration=PERIODS * 1e-3)
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    return reference_samples(scene, session.robot, stack.commands, PERIODS)


def _messages(bag: pathlib.Path) -> list[tuple[str, int, bytes]]:
    with Reader(bag) as reader:
        return [(c.topic, t, bytes(data)) for c, t, data in reader.messages()]


def _record(path: pathlib.Path, samples: list[Sample], background: bool) -> BagRecorder:
    urdf = load_robot().urdf_path.read_text(encoding='utf-8')
    with BagRecorder(path, {'scene': 'stand'}, urdf, background=background) as recorder:
        for sample in samples:
            recorder.write(sample)
    return recorder


def test_background_writer_writes_the_same_messages(tmp_path, samples):
    _record(tmp_path / 'inline', samples, background=False)
    recorder = _record(tmp_path / 'background', samples, background=True)
    inline, background = _messages(tmp_path / 'inline'), _messages(tmp_path / 'background')
    assert recorder.count == PERIODS
    assert len(background) == 1 + 6 * PERIODS  # the URDF, then 6 topics per sample
    assert background == inline


def test_the_bag_says_the_urdf_is_latched_and_replay_offers_it_so(tmp_path, samples):
    """/robot_description is recorded with the QoS the simulator offers it with (transient
    local, reliable, depth 1), which ``ros2 bag play`` and Foxglove replay; the live and
    replayed publishers use that profile."""
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
    from rosbags.interfaces import QosDurability, QosReliability

    from iceskate_sim.ros.node_support import LATCHED_QOS
    _record(tmp_path / 'bag', samples[:3], background=False)
    with Reader(tmp_path / 'bag') as reader:
        offered = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    (urdf,) = offered.pop('/robot_description')
    assert (urdf.durability, urdf.reliability, urdf.depth) == (
        QosDurability.TRANSIENT_LOCAL, QosReliability.RELIABLE, 1)
    assert offered and not any(offered.values())  # the others: as a plain reliable topic
    assert (LATCHED_QOS.durability, LATCHED_QOS.reliability, LATCHED_QOS.depth) == (
        DurabilityPolicy.TRANSIENT_LOCAL, ReliabilityPolicy.RELIABLE, 1)


def test_the_background_writer_runs_at_idle_priority(tmp_path, samples):
    """The writer takes only the CPU time the run leaves (SCHED_IDLE), whatever the parent's
    scheduling; the parent's stays as it was."""
    before = os.sched_getscheduler(0)
    urdf = load_robot().urdf_path.read_text(encoding='utf-8')
    with BagRecorder(tmp_path / 'bag', {'scene': 'stand'}, urdf,
                     background=True) as recorder:
        recorder.write(samples[0])
        assert os.sched_getscheduler(recorder._process.pid) == os.SCHED_IDLE
    assert os.sched_getscheduler(0) == before


def test_a_failing_background_writer_raises_and_leaves_a_closed_bag(tmp_path, samples,
                                                                    monkeypatch):
    def broken(self, record):
        raise OSError('disk full')
    monkeypatch.setattr(recording.RecordEncoder, 'encode_block', broken)  # forked along
    with pytest.raises(SimulationError, match='bag writer .* failed: OSError: disk full'):
        _record(tmp_path / 'bag', samples, background=True)
    assert [topic for topic, _, _ in _messages(tmp_path / 'bag')] == ['/robot_description']


@pytest.fixture(scope='module')
def skate_records() -> list[recording.BagRecord]:
    """1.5 s of a fast skate gait: support exchanges, heel strikes, several gait modes (the
    records of the native loop's blocks)."""
    scene = replace(load_scene(FAST_SKATE), duration=1.5, record_bag=False)
    return _native_records(scene)


def _native_records(scene) -> list[recording.BagRecord]:
    """The records the native loop's blocks of ``scene`` pack (``RecordBlock.of_columns``)."""
    native = Session(scene)
    stack = ControlStack(scene, native.robot, native.observation())
    blocks = []
    record_block = native._record_block
    native._record_block = lambda block, first: (blocks.append(block), record_block(block, first))
    while not native.done:
        native.run_periods(stack, 250)
    packed = [recording.RecordBlock.of_columns(
        block, dict(zip(block['sources'], block['efforts'], strict=True)), block['present'],
        native.sim.events) for block in blocks]
    return [block.record(k) for block in packed for k in range(len(block))]


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
    # every period before the failing one (which ended at sim_time_s) is in the bag
    assert 0 < len(clock) == round(metrics['sim_time_s'] * 1000) - 1 < 1500
    assert clock == [k * 1_000_000 for k in range(len(clock))]


def _rosbags_bytes(factory: recording.MessageFactory,
                   record: recording.BagRecord) -> dict[str, bytes]:
    return {topic: bytes(factory.typestore.serialize_cdr(message, recording.TOPICS[topic]))
            for topic, message in factory.record_messages(record).items()}


def test_the_encoder_writes_what_rosbags_serialises(skate_records):
    factory = recording.MessageFactory()
    encoder = recording.RecordEncoder(factory)
    for record in skate_records:
        assert encoder.encode(record) == _rosbags_bytes(factory, record)
    layouts = [layout for by_topic in encoder._layouts.values() for layout in by_topic.values()]
    assert len(encoder._layouts) >= 10 and len({r.mode for r in skate_records}) >= 3
    assert all(layout is not None for layout in layouts)  # every key learned, none fell back


def test_the_encoder_handles_non_finite_and_missing_values(skate_records):
    factory = recording.MessageFactory()
    encoder = recording.RecordEncoder(factory, capacity=2)  # evicts as it goes
    nan, inf = float('nan'), float('inf')
    edits = [{6: nan}, {2: nan}, {6: inf, 2: inf}, {10: nan, 11: -inf, 12: -0.0}, {-1: nan}]
    for record in skate_records[::150]:
        for edit in edits:
            values = record.values.copy()
            for i, value in edit.items():
                values[i] = value
            for cause in (record.last_cause, None):
                changed = record._replace(values=values, last_cause=cause)
                assert encoder.encode(changed) == _rosbags_bytes(factory, changed)


def test_the_encoder_falls_back_to_rosbags_when_no_layout_fits(skate_records, monkeypatch):
    monkeypatch.setattr(recording, 'sentinels', lambda size: np.full(size, 0.5))  # ambiguous
    factory = recording.MessageFactory()
    encoder = recording.RecordEncoder(factory)
    for record in skate_records[::100]:
        assert encoder.encode(record) == _rosbags_bytes(factory, record)
    layouts = [layout for by_topic in encoder._layouts.values() for layout in by_topic.values()]
    assert layouts and all(layout is None for layout in layouts)


def _as_bytes(encoded: dict[str, list]) -> list[dict[str, bytes]]:
    topics = list(encoded)
    return [{topic: bytes(encoded[topic][k]) for topic in topics}
            for k in range(len(encoded[topics[0]]))]


def test_a_block_encodes_as_its_records_one_by_one(skate_records):
    """``encode_block`` gives each record's bytes as ``encode`` and rosbags do, over gait modes,
    support exchanges, steps and causes, with far fewer layouts than discrete states (the
    side, pivot and step index are patched, not keyed)."""
    factory = recording.MessageFactory()
    block = recording.RecordBlock.of_records(skate_records)
    for k, record in enumerate(skate_records):
        got = block.record(k)
        assert got._replace(values=None) == record._replace(values=None)
        assert np.array_equal(got.values, record.values, equal_nan=True)
    by_block = recording.RecordEncoder(factory)
    got = _as_bytes(by_block.encode_block(block))
    by_record = recording.RecordEncoder(factory)
    assert got == [by_record.encode(record) for record in skate_records]
    for k in range(0, len(skate_records), 50):
        assert got[k] == _rosbags_bytes(factory, skate_records[k])
    states = {(r.mode, r.side, r.pivot, r.step_index) for r in skate_records}
    assert len({r.step_index for r in skate_records}) >= 3 and len(states) >= 10
    assert len(by_block._layouts) < len(states)
    layouts = [layout for by_topic in by_block._layouts.values() for layout in by_topic.values()]
    assert all(layout is not None for layout in layouts)
    assert any(layout.integers for layout in layouts)  # gait_state's side, pivot, step


def test_a_block_with_non_finite_values_encodes_as_its_records(skate_records):
    """Non-finite numbers, a stamp that cannot be one (then the same error as one record's)."""
    factory = recording.MessageFactory()
    nan, inf = float('nan'), float('inf')
    records = []
    for k, record in enumerate(skate_records[::60]):
        values = record.values.copy()
        values[[6, 2, 10, 11][k % 4]] = [nan, inf, nan, -inf][k % 4]
        records.append(record._replace(values=values))
    block = recording.RecordBlock.of_records(records)
    encoder = recording.RecordEncoder(factory)
    assert _as_bytes(encoder.encode_block(block)) == [_rosbags_bytes(factory, r)
                                                      for r in records]
    values = records[3].values.copy()
    values[1] = -1.0  # the support exchange's time: a stamp of a negative time
    broken = records[:3] + [records[3]._replace(values=values)]
    with pytest.raises(SimulationError, match='a stamp needs a finite time >= 0 s, got -1.0'):
        encoder.encode_block(recording.RecordBlock.of_records(broken))


def test_the_native_block_packs_what_the_oracle_samples_record():
    """``RecordBlock.of_columns`` (the native loop's samples) holds what ``bag_record`` packs of
    the oracle's samples of the same run: the same modes, sides, pivots, sources and causes,
    values equal to the round-off the two formulations of eq. (7) grow over 0.6 s."""
    scene = replace(load_scene('skate'), duration=0.6, record_bag=False)
    got = _native_records(scene)
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    records = [recording.bag_record(sample)
               for sample in reference_samples(scene, session.robot, stack.commands, 600)]
    assert len(got) == len(records) == 600
    for a, b in zip(got, records, strict=True):
        assert a._replace(values=None) == b._replace(values=None)
        np.testing.assert_allclose(a.values, b.values, rtol=1e-6, atol=1e-6)


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
    assert clock == [k * 1_000_000 for k in range(120)]


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


def test_a_spilling_trajectory_holds_what_one_in_memory_holds(tmp_path, samples):
    """Past its memory budget a Trajectory moves its samples to files (a long run's memory stays
    flat): the columns, a source that starts late included, equal the in-memory ones, on
    both ways of growing it, and the files go with the Trajectory."""
    from iceskate_sim.run.metrics import Trajectory
    kept, spilled = Trajectory(), Trajectory(tmp_path, spill_bytes=20_000)
    psi_d = np.array([0.0, 1.2, 0.0])
    for k, sample in enumerate(samples):
        if k == 150:  # a source that acts once, after samples were spilled
            sample = replace(sample, efforts={**sample.efforts, 'late': np.full(18, 0.5)})
        for trajectory in (kept, spilled):
            trajectory.append(sample, psi_d)
        if k % 100 == 99:  # blocks too
            columns = {key: value[-5:] for key, value in kept.arrays().items()
                       if not key.startswith('tau_')}
            efforts = {key[4:]: value[-5:] for key, value in kept.arrays().items()
                       if key.startswith('tau_')}
            for trajectory in (kept, spilled):
                trajectory.extend(columns, efforts)
    assert spilled._spilled > 0 and spilled._held <= 20_000
    a, b = kept.arrays(), spilled.arrays()
    assert a.keys() == b.keys() and len(kept) == len(spilled) == len(samples) + 10
    for key in a:
        assert np.array_equal(a[key], b[key], equal_nan=True), key
    acted = np.flatnonzero(a['tau_late'].any(axis=1))  # at sample 150 only: 0 elsewhere
    assert acted.tolist() == [155] and np.all(a['tau_late'][155] == 0.5)
    folder = spilled._spill_dir
    assert folder.parent == tmp_path and any(folder.iterdir())
    del spilled, trajectory, b
    import gc
    gc.collect()
    assert not folder.exists()
