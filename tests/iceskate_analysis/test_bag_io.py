"""Reading bags into arrays, and refusing the ones the analysis cannot use."""

from __future__ import annotations

import dataclasses
import pathlib
import shutil

import numpy as np
import pytest

from hostile import alias_bomb
from iceskate_analysis import bag_io
from iceskate_analysis.bag_io import BagReading, read_bag, resolve_bag_path
from iceskate_analysis.rows import join_rows
from iceskate_native.sample import SAMPLE_COLUMNS, routed
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.robot import COORDINATE_NAMES, N_COORDINATES


def test_read_bag_aligns_every_sample_of_a_run(sim_bag, spec):
    bag = read_bag(sim_bag)
    n = round(spec.tiny_skate['duration'] / spec.tiny_skate['control_period'])
    assert bag.n_samples == n
    assert np.all(np.diff(bag.t_ns) > 0)
    assert bag.t[0] == 0.0
    for name in ('q', 'v', 'qdd', 'effort_total'):
        assert getattr(bag, name).shape == (n, N_COORDINATES)
    assert bag.multipliers.shape == (n, 3)
    assert {'visual_lifting', 'posture', 'yaw', 'passive'} <= set(bag.efforts)
    assert set(bag.sources) == set(bag.efforts) - {'passive'}
    assert bag.scene_name == 'tiny_skate'
    assert bag.scene_parameters['floor']['mu'] == 0.005
    assert '<robot' in bag.urdf
    assert np.all(np.isfinite(bag.head_position))
    assert bag.notes == ()
    # the total effort of /joint_states is the sum of the recorded sources
    total = sum(bag.efforts[s] for s in bag.sources)
    np.testing.assert_allclose(bag.effort_total, total, rtol=0, atol=1e-9)


def test_every_column_a_bag_gives_back_is_the_runs(sim_bag):
    """The sample table's read-back routes: each column the bag gives back equals the one
    the run saved in trajectory.npz, to the bit."""
    bag = read_bag(sim_bag)
    with np.load(sim_bag.parent / 'trajectory.npz') as saved:
        trajectory = {name: saved[name] for name in saved.files}
    held = {f.name for f in dataclasses.fields(bag)}
    given = [column.name for topic in bag_io.REQUIRED_TOPICS
             for column, _ in routed(topic, read_back=True) if column.name in held]
    compared = [name for name in given if SAMPLE_COLUMNS[name].saved]
    assert {'q', 'v', 'qdd', 'mode', 'pivot', 'zmp_y', 'support_friction'} <= set(compared)
    for name in given:
        assert getattr(bag, name).shape[0] == bag.n_samples, name
    for name in compared:
        assert np.array_equal(getattr(bag, name), trajectory[name], equal_nan=True), name


def _edited_copy(source: pathlib.Path, target: pathlib.Path, edit) -> pathlib.Path:
    """A copy of bag ``source`` with each message passed through ``edit(topic, index, msg,
    typestore)`` (index: the message's number on its topic), which returns the messages to
    write in its place."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer
    with AnyReader([source]) as reader:
        writer = Writer(target, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        try:
            out = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=reader.typestore)
                   for c in reader.connections}
            seen: dict[str, int] = {}
            for conn, stamp, raw in reader.messages():
                index = seen[conn.topic] = seen.get(conn.topic, -1) + 1
                msg = reader.deserialize(raw, conn.msgtype)
                for written in edit(conn.topic, index, msg, reader.typestore):
                    writer.write(out[conn.id], stamp,
                                 reader.typestore.serialize_cdr(written, conn.msgtype))
        finally:
            writer.close()
    return target


def test_read_bag_joins_the_topics_on_their_stamps(sim_bag, tmp_path, monkeypatch):
    """A sample needs all three required topics (one missing drops it), a repeated stamp keeps
    its later message (the sources' order too), and a head pose missing at a sample leaves nan
    there alone."""
    import copy

    def edit(topic, index, msg, typestore):
        if topic == '/joint_dynamics' and index == 7:
            return []
        if topic == '/joint_dynamics' and index == 0:  # first its sources in reverse order
            earlier = copy.deepcopy(msg)
            n = len(msg.name)
            earlier.source_names = list(reversed(msg.source_names))
            earlier.source_efforts = msg.source_efforts.reshape(-1, n)[::-1].ravel().copy()
            return [earlier, msg]
        if topic == '/head_pose' and index == 3:
            return []
        if topic == '/joint_states' and index == 12:
            later = copy.deepcopy(msg)
            later.position[0] += 1.0
            return [msg, later]
        return [msg]
    whole = read_bag(sim_bag)
    bag = read_bag(_edited_copy(sim_bag, tmp_path / 'edited', edit))
    kept = np.delete(np.arange(whole.n_samples), 7)
    assert np.array_equal(bag.t_ns, whole.t_ns[kept])
    assert np.array_equal(bag.qdd, whole.qdd[kept])
    for source in whole.efforts:
        assert np.array_equal(bag.efforts[source], whole.efforts[source][kept])
    assert list(bag.efforts) == list(whole.efforts)
    expected = whole.q[kept].copy()
    expected[11, 0] += 1.0  # sample 12, the 12th kept: its later message
    assert np.array_equal(bag.q, expected)
    assert np.all(np.isnan(bag.head_position[3])) and np.all(np.isfinite(
        np.delete(bag.head_position, 3, axis=0)))
    assert bag.notes == ("1 sample(s) miss one of ['/gait_state', '/joint_dynamics', "
                         "'/joint_states'] and were dropped",
                         '2 message(s) repeated a header stamp; the later one was kept',
                         'the samples have 1 gap(s) (sampled every 0.001 s); the longest from '
                         't = 0.006000 s to 0.008000 s')
    monkeypatch.setattr(bag_io, 'LATE', 2)  # joins all along the bag
    for size in (1, 3, 7):  # read in blocks, the same samples and notes
        reading = BagReading(tmp_path / 'edited')
        blocks = list(reading.blocks(size))
        assert max(b.n_samples for b in blocks) <= size and len(blocks) >= bag.n_samples / size
        joined = join_rows(blocks)
        for name in ('t_ns', 'q', 'v', 'qdd', 'mode', 'step_index', 'last_transition_ns'):
            assert np.array_equal(getattr(joined, name), getattr(bag, name)), (size, name)
        assert np.array_equal(joined.head_position, bag.head_position, equal_nan=True)
        assert list(joined.efforts) == list(bag.efforts)
        assert all(np.array_equal(joined.efforts[s], bag.efforts[s]) for s in bag.efforts)
        assert tuple(reading.notes) == bag.notes


def test_the_stamps_of_a_thinned_bag_rounded_to_the_nanosecond_make_no_gap(sim_bag, tmp_path):
    """Stamps k * 4 ms written as float seconds are 1 ns apart from a regular grid: no gap."""
    def edit(topic, index, msg, typestore):
        if hasattr(msg, 'header'):
            msg.header.stamp.nanosec += index % 2  # 0.999999 ms and 1.000001 ms spacings
        return [msg]
    bag = read_bag(_edited_copy(sim_bag, tmp_path / 'jitter', edit))
    assert bag.notes == () and bag.n_samples == read_bag(sim_bag).n_samples


def test_read_bag_maps_gait_codes(synthetic_bag, spec):
    bag = read_bag(synthetic_bag)
    modes = [m for m, _, _ in spec.steps]
    assert bag.n_samples == len(spec.steps) * spec.samples_per_step
    for step, (mode, side, pivot) in enumerate(spec.steps):
        k = step * spec.samples_per_step
        assert int(bag.mode[k]) == mode
        assert bag.side_name(k) == side
        assert int(bag.step_index[k]) == step
        if mode == 2:  # q1 active: the pivot is recorded
            assert bag.pivot_name(k) == pivot
            assert bag.active[k, 1]
    assert sorted(set(bag.mode.tolist())) == sorted(modes)
    assert bag.t[np.argmax(bag.step_index >= 3)] == pytest.approx(
        3 * spec.samples_per_step * spec.dt)


def test_a_run_directory_resolves_to_its_bag(sim_bag):
    assert resolve_bag_path(sim_bag.parent) == sim_bag


@pytest.mark.parametrize('topic, what', [
    ('/joint_dynamics', 'joint accelerations'),
    ('/gait_state', 'gait mode'),
    ('/joint_states', 'joint positions'),
])
def test_read_bag_refuses_a_bag_without_a_required_topic(sim_bag, bag_without, topic, what):
    broken = bag_without(sim_bag, topic)
    with pytest.raises(SimulationError, match=f'has no topic {topic} .*{what}'):
        read_bag(broken)


def test_a_bag_without_head_pose_is_read_with_a_note(sim_bag, bag_without):
    bag = read_bag(bag_without(sim_bag, '/head_pose'))
    assert np.all(np.isnan(bag.head_position))
    assert any('/head_pose' in note for note in bag.notes)


def test_read_bag_refuses_a_truncated_bag(truncated_bag):
    with pytest.raises(SimulationError, match='truncated or corrupt'):
        read_bag(truncated_bag)


def test_the_mcap_file_of_a_closed_bag_reads_as_the_bag(sim_bag):
    (mcap,) = sim_bag.glob('*.mcap')
    bag = read_bag(mcap)
    assert bag.path == sim_bag and bag.notes == () and bag.scene_name == 'tiny_skate'


def test_a_bag_split_over_two_files_reads_as_the_whole(tmp_path, sim_bag):
    """A bag split over several .mcap files (as ``ros2 bag record --max-bag-size`` leaves it),
    each file with its own channel of a topic, gives the samples of the whole bag."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer
    with AnyReader([sim_bag]) as reader:
        stamps = sorted(stamp for _, stamp, _ in reader.messages())
        middle = stamps[len(stamps) // 2]
        parts = []
        for k, keep in enumerate((lambda s: s < middle, lambda s: s >= middle)):
            writer = Writer(tmp_path / f'part{k}', version=9, storage_plugin=StoragePlugin.MCAP)
            writer.open()
            try:
                out = {c.id: writer.add_connection(c.topic, c.msgtype,
                                                   typestore=reader.typestore)
                       for c in reader.connections}
                for conn, stamp, raw in reader.messages():
                    if keep(stamp):
                        writer.write(out[conn.id], stamp, raw)
            finally:
                writer.close()
            parts.append(tmp_path / f'part{k}')
    shutil.move(next(parts[1].glob('*.mcap')), parts[0] / 'part0_1.mcap')
    assert len(list(parts[0].glob('*.mcap'))) == 2
    whole, split = read_bag(sim_bag), read_bag(parts[0])
    assert split.n_samples == whole.n_samples and split.notes == whole.notes
    np.testing.assert_array_equal(split.t_ns, whole.t_ns)
    for name in ('q', 'v', 'qdd', 'effort_total', 'multipliers', 'head_position'):
        np.testing.assert_array_equal(getattr(split, name), getattr(whole, name))
    assert split.urdf == whole.urdf


def test_a_split_bag_s_files_are_read_in_the_order_they_were_recorded():
    """rosbag2 numbers a split bag's files without zero padding: _10 comes after _9."""
    names = [f'run_{k}.mcap' for k in (10, 2, 0, 11, 1, 9)]
    ordered = sorted((pathlib.Path(n) for n in names), key=bag_io._recording_order)
    assert [p.name for p in ordered] == [f'run_{k}.mcap' for k in (0, 1, 2, 9, 10, 11)]


def test_read_bag_rebuilds_a_bag_without_metadata_from_its_mcap_file(tmp_path, sim_bag):
    """A recording never closed (a killed run) has no metadata.yaml: every message of the
    .mcap file's complete chunks is read, and the notes say so."""
    target = tmp_path / 'no_metadata'
    shutil.copytree(sim_bag, target)
    (target / 'metadata.yaml').unlink()
    bag, whole = read_bag(target), read_bag(sim_bag)
    assert bag.n_samples == whole.n_samples and np.array_equal(bag.q, whole.q)
    assert np.array_equal(bag.efforts['passive'], whole.efforts['passive'])
    assert 'no metadata.yaml' in bag.notes[0] and 'rebuilt from' in bag.notes[0]
    assert bag.urdf == whole.urdf and bag.custom_data == {}


@pytest.mark.timeout(30)
def test_an_alias_bomb_in_a_bag_s_metadata_is_not_expanded(tmp_path, sim_bag):
    """A bag's metadata.yaml is read within the bounds of every YAML read: a crafted one (an
    alias bomb in its custom data) loses its custom data, and the samples read as before."""
    target = tmp_path / 'bomb'
    shutil.copytree(sim_bag, target)
    metadata = target / 'metadata.yaml'
    metadata.write_text(metadata.read_text().replace(
        'custom_data:', f'custom_data:\n    bomb: {alias_bomb()}', 1))
    bag, whole = read_bag(target), read_bag(sim_bag)
    assert whole.custom_data and bag.custom_data == {}
    assert np.array_equal(bag.q, whole.q)


def test_read_bag_refuses_a_missing_path(tmp_path):
    with pytest.raises(SimulationError, match='does not exist'):
        read_bag(tmp_path / 'nothing')


def _write(path: pathlib.Path, topics: dict[str, tuple[str, object]], typestore) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    try:
        for topic, (msgtype, message) in topics.items():
            conn = writer.add_connection(topic, msgtype, typestore=typestore)
            writer.write(conn, 0, typestore.serialize_cdr(message, msgtype))
    finally:
        writer.close()


def test_read_bag_refuses_a_topic_of_the_wrong_type(tmp_path):
    from iceskate_sim.recording.bag_types import make_typestore
    ts = make_typestore()
    string = ts.types['std_msgs/msg/String']
    path = tmp_path / 'wrong_type'
    _write(path, {'/joint_states': ('std_msgs/msg/String', string(data='x')),
                  '/gait_state': ('std_msgs/msg/String', string(data='x')),
                  '/joint_dynamics': ('std_msgs/msg/String', string(data='x'))}, ts)
    with pytest.raises(SimulationError, match='has message type std_msgs/msg/String, expected'):
        read_bag(path)


def test_read_bag_refuses_an_unknown_definition_of_our_message(tmp_path, sim_bag, bag_without):
    """A bag whose JointDynamics is another message under the same name (an old interface)."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    old = get_typestore(Stores.ROS2_JAZZY)
    old.register(get_types_from_msg('std_msgs/Header header\nstring[] name\n'
                                    'float64[] acceleration\n',
                                    'iceskate_interfaces/msg/JointDynamics'))
    source = bag_without(sim_bag, '/joint_dynamics')
    path = tmp_path / 'old_interface'
    with AnyReader([source]) as reader:
        writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        out = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=reader.typestore)
               for c in reader.connections}
        dyn = writer.add_connection('/joint_dynamics', 'iceskate_interfaces/msg/JointDynamics',
                                    typestore=old)
        msg_type = old.types['iceskate_interfaces/msg/JointDynamics']
        for conn, stamp, raw in reader.messages():
            writer.write(out[conn.id], stamp, raw)
            if conn.topic == '/joint_states':
                header = reader.deserialize(raw, conn.msgtype).header
                message = msg_type(header=header, name=list(COORDINATE_NAMES),
                                   acceleration=np.zeros(N_COORDINATES))
                writer.write(dyn, stamp, old.serialize_cdr(
                    message, 'iceskate_interfaces/msg/JointDynamics'))
        writer.close()
    with pytest.raises(SimulationError, match='/joint_dynamics.*incompatible message'):
        read_bag(path)


def _rewrite_joint_dynamics(source: pathlib.Path, path: pathlib.Path, change) -> pathlib.Path:
    """Copy the bag at ``source`` to ``path`` with ``change(msg)`` applied to /joint_dynamics."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer
    with AnyReader([source]) as reader:
        ts = reader.typestore
        writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        out = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=ts)
               for c in reader.connections}
        for conn, stamp, raw in reader.messages():
            if conn.topic == '/joint_dynamics':
                msg = reader.deserialize(raw, conn.msgtype)
                change(msg)
                raw = ts.serialize_cdr(msg, conn.msgtype)
            writer.write(out[conn.id], stamp, raw)
        writer.close()
    return path


@pytest.mark.parametrize('change, match', [
    (lambda m: setattr(m, 'source_efforts', m.source_efforts[:-1]),
     r'source_efforts has \d+ values for \d+ sources x 18 names'),
    (lambda m: setattr(m, 'source_names', [m.source_names[0]] * len(m.source_names)),
     'repeated source names'),
])
def test_read_bag_refuses_a_malformed_effort_breakdown(tmp_path, sim_bag, change, match):
    broken = _rewrite_joint_dynamics(sim_bag, tmp_path / 'broken', change)
    with pytest.raises(SimulationError, match=f'/joint_dynamics at .*{match}'):
        read_bag(broken)


def test_the_breakdown_survives_a_rewrite_unchanged(tmp_path, sim_bag):
    """The copy above changes nothing by itself (the refusals come from the changes)."""
    same = read_bag(_rewrite_joint_dynamics(sim_bag, tmp_path / 'same', lambda m: None))
    original = read_bag(sim_bag)
    assert set(same.efforts) == set(original.efforts)
    for source, tau in original.efforts.items():
        np.testing.assert_array_equal(same.efforts[source], tau)


def test_reading_a_bag_keeps_its_samples_as_arrays(tmp_path):
    """What read_bag needs grows with the bag about as its arrays do (the rows are written into
    arrays as the messages are decoded; no object per message is kept): from a 1 s to a 4 s
    bag its peak grows by less than 1.5 times the growth of the arrays it returns."""
    import dataclasses
    import tracemalloc

    from iceskate_bringup.runner import run
    from iceskate_bringup.scene import load_scene
    stand = load_scene(str(pathlib.Path(__file__).resolve().parents[1] / 'integration' / 'data'
                           / 'tiny_stand.yaml'))

    def measured(duration: float) -> tuple[int, int]:  # (peak, arrays) [bytes]
        out = tmp_path / f'{duration:g}s'
        run(dataclasses.replace(stand, duration=duration), out, progress=False, picture=False)
        read_bag(out / 'bag')  # the imports and caches of a first read
        tracemalloc.start()
        try:
            bag = read_bag(out / 'bag')
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert bag.n_samples == round(duration * 1000)
        arrays = [getattr(bag, f.name) for f in dataclasses.fields(bag)]
        arrays = [x for x in arrays if isinstance(x, np.ndarray)] + list(bag.efforts.values())
        return peak, sum(x.nbytes for x in arrays)
    (short_peak, short_arrays), (long_peak, long_arrays) = measured(1.0), measured(4.0)
    assert long_peak - short_peak < 1.5 * (long_arrays - short_arrays), (
        short_peak, long_peak, short_arrays, long_arrays)


def test_a_source_that_comes_later_counts_zero_before_in_every_block(sim_bag, tmp_path,
                                                                    monkeypatch):
    """A source first carried at the 9th sample (as a push is): the blocks before it hold 0,
    and the analysis in blocks (its sums, its CSV) equals the analysis of the whole run."""
    from iceskate_analysis.coupling import analyse_bag, analyse_case

    def edit(topic, index, msg, typestore):
        if topic == '/joint_dynamics' and index >= 8:
            n = len(msg.name)
            msg.source_names = [*msg.source_names, 'later']
            msg.source_efforts = np.concatenate([msg.source_efforts, np.full(n, 0.5)])
        return [msg]
    path = _edited_copy(sim_bag, tmp_path / 'later', edit)
    whole = read_bag(path)
    assert list(whole.efforts)[-1] == 'later'
    assert np.all(whole.efforts['later'][:8] == 0.0) and np.all(whole.efforts['later'][8:] == 0.5)
    monkeypatch.setattr(bag_io, 'LATE', 2)
    texts, summaries = [], []
    for size in (3, whole.n_samples):
        csv = tmp_path / f'series_{size}.csv'
        summaries.append(analyse_bag(BagReading(path), 'c', 11, csv=csv, size=size).summary())
        texts.append(csv.read_text())
    assert texts[0] == texts[1] and 'q11.tau[later]' in texts[0].splitlines()[0]
    rms = [s['joints']['q11']['rms_tau_by_source']['later'] for s in summaries]
    assert rms[0] == pytest.approx(rms[1], rel=1e-12)
    assert analyse_case(whole, 'c', 11, size=3).summary()['rms_tau_by_source'] == \
        pytest.approx(summaries[1]['rms_tau_by_source'], rel=1e-12)


@pytest.mark.parametrize('late, kept', [(2, 'first'), (256, 'later')])
def test_a_message_over_late_samples_after_its_stamp_is_dropped_with_a_note(
        sim_bag, tmp_path, monkeypatch, late, kept):
    """A /joint_states message sent again 10 samples later: joined as the later message of its
    stamp while within ``LATE`` samples, else dropped, whatever the blocks, and the notes say
    which."""
    import copy
    held = {}

    def edit(topic, index, msg, typestore):
        if topic == '/joint_states' and index == 5:
            held['again'] = copy.deepcopy(msg)
            held['again'].position[0] += 1.0
        if topic == '/joint_states' and index == 15:
            return [msg, held['again']]
        return [msg]
    path = _edited_copy(sim_bag, tmp_path / 'again', edit)
    original = read_bag(sim_bag)
    monkeypatch.setattr(bag_io, 'LATE', late)
    note = ('1 message(s) came 2 samples or more after their header stamp and were dropped'
            if kept == 'first' else
            '1 message(s) repeated a header stamp; the later one was kept')
    for size in (1, 3, 100):  # whenever the samples are joined
        reading = BagReading(path)
        bag = join_rows(list(reading.blocks(size)))
        assert bag.n_samples == original.n_samples
        assert bag.q[5, 0] == original.q[5, 0] + (1.0 if kept == 'later' else 0.0)
        assert reading.notes == [note]
