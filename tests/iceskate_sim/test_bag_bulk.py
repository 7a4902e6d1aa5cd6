"""bag_bulk.write_many: the same MCAP bag, byte for byte, as rosbags' Writer.write one by one."""

from dataclasses import replace
import pathlib

import numpy as np
import pytest
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.rosbag2.writer import CompressionFormat, CompressionMode

from iceskate_bringup.composition import ControlStack
from iceskate_bringup.scene import load_scene
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.stamps import seconds_to_ns
from iceskate_sim.recording.bag_bulk import write_many
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.recording.links import LinkTransforms
from iceskate_sim.recording.messages import RECORDED_TOPICS, Events, SampleMessages
from iceskate_sim.recording.messages import TOPICS as RECORDED_TYPES  # this file has TOPICS
from iceskate_sim.run.session import Session

TOPICS = {'/clock': 'rosgraph_msgs/msg/Clock', '/chatter': 'std_msgs/msg/String',
          '/big': 'std_msgs/msg/String'}


def _messages(count: int, seed: int = 0) -> list[tuple[str, int, bytes]]:
    """(topic, stamp [ns], CDR-like data) with lengths from 1 byte to 40 kB, so that chunks
    fill up at different messages; stamps out of order now and then."""
    rng = np.random.default_rng(seed)
    topics = list(TOPICS)
    out = []
    for k in range(count):
        topic = topics[int(rng.integers(len(topics)))]
        size = int(rng.integers(1, 40_000 if topic == '/big' else 200))
        stamp = 1_000_000 * k + int(rng.integers(-3_000_000, 3_000_000)) + 10_000_000
        out.append((topic, stamp, rng.bytes(size)))
    return out


def _write(folder: pathlib.Path, messages: list[tuple[str, int, bytes]], bulk: bool,
           blocks: int | list[list[int]] = 3, topics: dict[str, str] = TOPICS,
           **options: object) -> pathlib.Path:
    """The bag ``folder/bag`` (the same name everywhere: the metadata holds it) of the
    connections ``topics``; ``bulk``: ``write_many`` of ``blocks`` (that many near-equal
    blocks, or the indices of each block's messages), else ``Writer.write`` one by one."""
    path = folder / 'bag'
    folder.mkdir()
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    if options:
        writer.set_compression(**options)
    writer.open()
    ts = make_typestore()
    connections = {topic: writer.add_connection(topic, msgtype, typestore=ts)
                   for topic, msgtype in topics.items()}
    rows = [(connections[topic], stamp, data) for topic, stamp, data in messages]
    if bulk:
        for block in (np.array_split(np.arange(len(rows)), blocks) if isinstance(blocks, int)
                      else blocks):
            write_many(writer, [rows[k] for k in block])
    else:
        for connection, stamp, data in rows:
            writer.write(connection, stamp, data)
    writer.close()
    return path


@pytest.mark.parametrize('count', [0, 1, 7, 400])
def test_the_bag_is_the_same_file_as_one_by_one(tmp_path, count):
    """400 messages of up to 40 kB make three 1 MiB chunks or more, closed mid-block."""
    messages = _messages(count)
    single = _write(tmp_path / 'single', messages, bulk=False)
    bulk = _write(tmp_path / 'bulk', messages, bulk=True)
    for name in ('bag.mcap', 'metadata.yaml'):
        assert (bulk / name).read_bytes() == (single / name).read_bytes(), name
    if count == 400:
        assert sum(len(data) for _, _, data in messages) > 2 * 2**20  # three chunks or more
    with Reader(bulk) as reader:
        got = [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]
    assert sorted(got, key=lambda m: m[1]) == sorted(messages, key=lambda m: m[1])


def test_blocks_of_any_size_give_the_same_file(tmp_path):
    messages = _messages(120, seed=3)
    files = [(_write(tmp_path / str(n), messages, bulk=True, blocks=n) / 'bag.mcap').read_bytes()
             for n in (1, 5, 120)]
    assert files[0] == files[1] == files[2]


def test_compressed_bags_are_the_same_file_too(tmp_path):
    """Chunk compression (zstd, storage mode) is the storage's; per-message compression goes
    one by one through Writer.write."""
    messages = _messages(60, seed=5)
    for mode in (CompressionMode.STORAGE, CompressionMode.MESSAGE):
        options = {'fmt': CompressionFormat.ZSTD, 'mode': mode}
        single = _write(tmp_path / f'single-{mode.name}', messages, bulk=False, **options)
        bulk = _write(tmp_path / f'bulk-{mode.name}', messages, bulk=True, **options)
        assert sorted(p.name for p in single.iterdir()) == sorted(p.name for p in bulk.iterdir())
        for path in single.iterdir():
            assert (bulk / path.name).read_bytes() == path.read_bytes(), (mode, path.name)


@pytest.fixture(scope='module')
def sample_messages() -> tuple[list[tuple[str, int, bytes]], list[list[int]]]:
    """The messages of 400 periods of the stand scene, as the bag writer has them: each native
    block's samples (blocks of 150 periods), sample by sample, topics in ``RECORDED_TOPICS``
    order, stamped with the sample's time; and the messages of each block."""
    scene = replace(load_scene('stand'), duration=0.4, record_bag=False)
    session = Session(scene)
    stack = ControlStack(scene, session.robot, session.observation())
    encoder = SampleMessages(make_typestore(), LinkTransforms(session.robot.urdf_model))
    messages, blocks = [], []
    record_block = session._record_block

    def record(block: dict, first: int) -> None:
        record_block(block, first)
        encoded = encoder.encode(block, Events.of(block['last_event'], session.sim.events))
        start = len(messages)
        for k, t in enumerate(block['t'].tolist()):
            messages.extend((topic, seconds_to_ns(t), encoded[topic][k])
                            for topic in RECORDED_TOPICS)
        blocks.append(list(range(start, len(messages))))
    session._record_block = record
    while not session.done:
        session.run_periods(stack, 150)
    return messages, blocks


def test_the_blocks_of_a_run_give_the_same_file_as_one_by_one(tmp_path, sample_messages):
    """The messages of native blocks (tens of kB a sample with /tf), written a block at a
    time, make the file ``Writer.write`` makes of them one by one, over several chunks."""
    messages, blocks = sample_messages
    assert len(blocks) == 3 and len(messages) == 6 * 400
    assert sum(len(data) for _, _, data in messages) > 2**20  # two chunks or more
    single = _write(tmp_path / 'single', messages, bulk=False, topics=RECORDED_TYPES)
    bulk = _write(tmp_path / 'bulk', messages, bulk=True, blocks=blocks, topics=RECORDED_TYPES)
    for name in ('bag.mcap', 'metadata.yaml'):
        assert (bulk / name).read_bytes() == (single / name).read_bytes(), name
    with Reader(bulk) as reader:
        got = [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]
    assert got == messages


def test_a_connection_the_bag_does_not_have_is_refused(tmp_path):
    other = Writer(tmp_path / 'other', version=9, storage_plugin=StoragePlugin.MCAP)
    other.open()
    stranger = other.add_connection('/clock', TOPICS['/clock'], typestore=make_typestore())
    writer = Writer(tmp_path / 'bag', version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    writer.add_connection('/chatter', TOPICS['/chatter'], typestore=make_typestore())
    with pytest.raises(SimulationError, match='a message of a connection it does not have'):
        write_many(writer, [(stranger, 1, b'\x00')])
    writer.close()
    other.close()


def test_a_writer_that_is_not_open_is_refused(tmp_path):
    writer = Writer(tmp_path / 'bag', version=9, storage_plugin=StoragePlugin.MCAP)
    with pytest.raises(SimulationError, match='is not open'):
        write_many(writer, [])
