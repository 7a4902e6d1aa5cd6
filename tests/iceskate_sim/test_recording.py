"""The bag recorder: a background writer process writes the same bag as an in-process one, and
its failures and the run's failures still leave a closed, readable bag."""

from dataclasses import replace
import json
import pathlib

import numpy as np
import pytest
from rosbags.rosbag2 import Reader

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.runner import run
from iceskate_bringup.scene import load_scene
from iceskate_sim import recording
from iceskate_sim.errors import SimulationError
from iceskate_sim.recording import BATCH, BagRecorder, Sample
from iceskate_sim.robot import load_robot
from iceskate_sim.session import Session
from iceskate_sim.simulation import Simulator

PERIODS = 2 * BATCH + 17  # two full batches and a partial one


@pytest.fixture(scope='module')
def samples() -> list[Sample]:
    """The first periods of the stand scene (push, visual lifting, posture stabiliser)."""
    scene = replace(load_scene('stand'), duration=PERIODS * 1e-3)
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    return [session.step(stack.commands(session.observation())) for _ in range(PERIODS)]


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


def test_a_failing_background_writer_raises_and_leaves_a_closed_bag(tmp_path, samples,
                                                                    monkeypatch):
    def broken(self, record):
        raise OSError('disk full')
    monkeypatch.setattr(recording.RecordEncoder, 'encode', broken)  # forked along
    with pytest.raises(SimulationError, match='bag writer .* failed: OSError: disk full'):
        _record(tmp_path / 'bag', samples, background=True)
    assert [topic for topic, _, _ in _messages(tmp_path / 'bag')] == ['/robot_description']


def test_a_run_that_fails_leaves_a_readable_bag_of_the_periods_before(tmp_path, monkeypatch):
    failing_at = BATCH + 5

    advance = Simulator.advance

    def advance_until_failure(sim, *args):
        if sim.stats.control_periods == failing_at:
            raise SimulationError('diverged on purpose')
        return advance(sim, *args)
    monkeypatch.setattr(Simulator, 'advance', advance_until_failure)
    scene = load_scene('stand')  # the Python engine: the runner advances period by period
    scene = replace(scene, duration=0.5, simulator=replace(scene.simulator, engine='python'))
    with pytest.raises(SimulationError, match='on purpose'):
        run(scene, tmp_path, progress=False)
    clock = [t for topic, t, _ in _messages(tmp_path / 'bag') if topic == '/clock']
    assert len(clock) == failing_at
    assert clock[-1] == (failing_at - 1) * 1_000_000


@pytest.fixture(scope='module')
def skate_records() -> list[recording.BagRecord]:
    """1.5 s of the skate scene: support exchanges, heel strikes, several gait modes."""
    scene = load_scene('skate')
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    return [recording.bag_record(session.step(stack.commands(session.observation())))
            for _ in range(1500)]


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
