"""mcap_bag.Bag: the bag reads back the same through rosbags' and mcap's readers (checksums,
indexes, summary) and holds what rosbags' own writer would write of the same messages."""

import pathlib

from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
import numpy as np
import pytest
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys.store import Typestore
import yaml

from iceskate_sim.recording.bag_types import OFFERED_QOS, make_typestore
from iceskate_sim.recording.mcap_bag import CHUNK_BYTES, Bag

TOPICS = {'/clock': 'rosgraph_msgs/msg/Clock', '/chatter': 'std_msgs/msg/String',
          '/robot_description': 'std_msgs/msg/String'}
Message = tuple[str, int, bytes]
#: /robot_description's QoS as rosbags states it: latched (durations 0: the defaults).
LATCHED = Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
              QosTime(0, 0), QosTime(0, 0), QosLiveliness.AUTOMATIC, QosTime(0, 0), False)


@pytest.fixture(scope='module')
def typestore() -> Typestore:
    return make_typestore()


def _instants(count: int, seed: int = 0) -> list[tuple[int, dict[str, bytes]]]:
    """``count`` instants (stamp [ns], topic -> data): /clock and /chatter at each, /chatter of
    1 byte to 40 kB, so that chunks fill up at different instants; stamps out of order now
    and then."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(count):
        stamp = 1_000_000 * k + int(rng.integers(-3_000_000, 3_000_000)) + 10_000_000
        out.append((stamp, {'/clock': rng.bytes(12),
                            '/chatter': rng.bytes(int(rng.integers(1, 40_000)))}))
    return out


def _messages(instants: list[tuple[int, dict[str, bytes]]]) -> list[Message]:
    return [(topic, stamp, data) for stamp, row in instants for topic, data in row.items()]


def _write(path: pathlib.Path, typestore: Typestore, instants: list, blocks: int = 3,
           custom: dict[str, str] | None = None) -> pathlib.Path:
    """The bag at ``path``: the URDF at 0 ns, then ``instants`` in ``blocks`` calls."""
    bag = Bag(path, TOPICS, typestore, OFFERED_QOS, custom or {'scene': 'test'})
    bag.write('/robot_description', 0, b'urdf')
    for block in np.array_split(np.arange(len(instants)), blocks):
        rows = [instants[k] for k in block]
        bag.write_instants([stamp for stamp, _ in rows],
                           {topic: [row[topic] for _, row in rows] for topic in ('/clock',
                                                                                 '/chatter')})
    bag.close()
    return path


def _read_rosbags(path: pathlib.Path) -> list[Message]:
    with Reader(path) as reader:
        return [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]


def _by_time(messages: list[Message]) -> list[Message]:
    return sorted(messages, key=lambda m: m[1])


@pytest.mark.parametrize('count', [0, 1, 7, 150])
def test_both_readers_give_back_every_message(tmp_path, typestore, count):
    """150 instants of up to 40 kB make three 1 MiB chunks or more, closed mid-block: the
    file's records pass mcap's checks (CRCs, summary, indexes) and both readers give back
    the messages, in file order by the chunk indexes and in time order by rosbags."""
    instants = _instants(count)
    written = [('/robot_description', 0, b'urdf'), *_messages(instants)]
    path = _write(tmp_path / 'bag', typestore, instants)
    with (path / 'bag.mcap').open('rb') as stream:
        records = list(StreamReader(stream, validate_crcs=True).records)
    with (path / 'bag.mcap').open('rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        summary = reader.get_summary()
        got = [(channel.topic, message.log_time, message.data) for _, channel, message
               in reader.iter_messages(log_time_order=False)]
    assert got == written
    assert summary.statistics.message_count == len(written)
    assert summary.statistics.channel_message_counts == {1: count, 2: count, 3: 1}
    assert summary.statistics.chunk_count == len(summary.chunk_indexes) >= 1
    assert all(index.uncompressed_size < CHUNK_BYTES + 40_100
               for index in summary.chunk_indexes)
    if count == 150:
        assert len(summary.chunk_indexes) >= 3 and len(records) > 10
    assert _by_time(_read_rosbags(path)) == _by_time(written)


def test_blocks_of_any_size_give_the_same_file(tmp_path, typestore):
    instants = _instants(120, seed=3)
    files = [(_write(tmp_path / str(n) / 'bag', typestore, instants, blocks=n)
              / 'bag.mcap').read_bytes() for n in (1, 5, 120)]
    assert files[0] == files[1] == files[2]


def test_the_bag_holds_what_rosbags_writer_writes(tmp_path, typestore):
    """rosbags' own writer, message by message, as the independent reference: the same
    messages, connections (type, definition, hash, QoS) and metadata (counts, times,
    custom_data) through rosbags' reader."""
    instants = _instants(60, seed=5)
    ours = _write(tmp_path / 'ours' / 'bag', typestore, instants, custom={'scene': 'x'})
    theirs = tmp_path / 'theirs' / 'bag'
    theirs.parent.mkdir()
    with Writer(theirs, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        writer.set_custom_data('scene', 'x')
        connections = {topic: writer.add_connection(
            topic, msgtype, typestore=typestore,
            offered_qos_profiles=[LATCHED] if topic == '/robot_description' else [])
            for topic, msgtype in TOPICS.items()}
        for topic, stamp, data in [('/robot_description', 0, b'urdf'), *_messages(instants)]:
            writer.write(connections[topic], stamp, data)
    with Reader(ours) as mine, Reader(theirs) as reference:
        assert [(c.topic, c.msgtype, c.msgdef, c.digest, c.msgcount, c.ext)
                for c in mine.connections] == [
            (c.topic, c.msgtype, c.msgdef, c.digest, c.msgcount, c.ext)
            for c in reference.connections]
        for field in ('duration', 'start_time', 'end_time', 'message_count'):
            assert getattr(mine, field) == getattr(reference, field), field
    assert _read_rosbags(ours) == _read_rosbags(theirs)
    info, reference_info = (
        yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
        for path in (ours, theirs))
    for key in ('version', 'storage_identifier', 'duration', 'starting_time', 'message_count',
                'topics_with_message_count', 'relative_file_paths', 'files', 'custom_data'):
        assert info[key] == reference_info[key], key


def test_the_urdf_is_offered_latched(tmp_path, typestore):
    path = _write(tmp_path / 'bag', typestore, _instants(3))
    with Reader(path) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert qos == {'/clock': [], '/chatter': [], '/robot_description': [LATCHED]}


def test_an_existing_folder_or_unknown_topic_is_refused(tmp_path, typestore):
    path = _write(tmp_path / 'bag', typestore, [])
    with pytest.raises(FileExistsError):
        Bag(path, TOPICS, typestore, OFFERED_QOS, {})
    bag = Bag(tmp_path / 'other', TOPICS, typestore, OFFERED_QOS, {})
    with pytest.raises(KeyError):
        bag.write('/stranger', 1, b'\x00')
    bag.close()
    bag.close()  # idempotent
    assert _read_rosbags(bag.path) == []


def test_an_aborted_bag_has_no_metadata_but_its_chunks(tmp_path, typestore):
    """A recording cut short: the chunks written so far are whole records; no summary."""
    bag = Bag(tmp_path / 'bag', TOPICS, typestore, OFFERED_QOS, {})
    instants = _instants(80, seed=7)
    bag.write_instants([stamp for stamp, _ in instants],
                       {topic: [row[topic] for _, row in instants]
                        for topic in ('/clock', '/chatter')})
    bag._file.close()  # as it is: no index, no metadata.yaml
    assert not (bag.path / 'metadata.yaml').exists()
    kinds = set()
    with (bag.path / 'bag.mcap').open('rb') as stream, pytest.raises(EndOfFile):
        for record in StreamReader(stream, emit_chunks=True).records:
            kinds.add(type(record).__name__)
    assert {'Header', 'Schema', 'Channel', 'Chunk', 'MessageIndex'} <= kinds
    assert 'Footer' not in kinds


class _FillingFile:
    """A file that takes ``room`` more bytes (the last write short), then raises ENOSPC once:
    what follows goes into the room the bag kept (given back as it closes)."""

    def __init__(self, file, room: int) -> None:
        self.file, self.room, self.state = file, room, 'filling'

    def write(self, data) -> int:
        if self.state == 'full':
            self.state = 'freed'
            raise OSError(28, 'No space left on device')
        if self.state == 'filling' and len(data) >= self.room:
            self.state = 'full'
            return self.file.write(data[:self.room])  # a short write
        self.room -= len(data)
        return self.file.write(data)

    def __getattr__(self, name):
        return getattr(self.file, name)


def test_a_full_disk_cuts_the_chunk_off_and_the_bag_closes_with_the_others(tmp_path, typestore):
    """The disk fills up in the middle of the third chunk: that write raises, the chunk is cut
    off the file, and ``close`` (in the room the bag kept for it) finishes a bag that both
    readers take, holding exactly the instants of the two chunks before, with its counts."""
    instants = _instants(400, seed=7)  # 8 MB: the third chunk fills up
    bag = Bag(tmp_path / 'bag', TOPICS, typestore, OFFERED_QOS, {'scene': 'full'})
    assert (tmp_path / 'bag' / '.summary.room').stat().st_size >= 256 << 10
    bag.write('/robot_description', 0, b'urdf')
    written = []
    with pytest.raises(OSError, match='No space left'):
        for stamp, row in instants:
            if len(bag._chunk_indexes) == 2 and not isinstance(bag._file, _FillingFile):
                bag._file = _FillingFile(bag._file, 100_000)  # less than a chunk
            bag.write_instants([stamp], {topic: [row[topic]] for topic in ('/clock', '/chatter')})
            written.append((stamp, row))
    kept = [('/robot_description', 0, b'urdf'), *_messages(written)]
    bag.close()
    assert not (tmp_path / 'bag' / '.summary.room').exists()
    with (tmp_path / 'bag' / 'bag.mcap').open('rb') as stream:
        reader = make_reader(stream, validate_crcs=True)
        summary = reader.get_summary()
        got = [(c.topic, m.log_time, m.data) for _, c, m in reader.iter_messages(
            log_time_order=False)]
    assert summary.statistics.chunk_count == 2
    assert got == kept[:len(got)] and 2 < len(got) < len(kept)  # the open chunk's are lost
    assert summary.statistics.message_count == len(got)
    assert _by_time(_read_rosbags(tmp_path / 'bag')) == _by_time(got)
    with Reader(tmp_path / 'bag') as reader:
        assert reader.message_count == len(got)
        assert reader.end_time == max(t for _, t, _ in got) + 1


def test_a_last_chunk_the_disk_has_no_room_for_is_an_error_of_close(tmp_path, typestore):
    """The open chunk cannot be written when the bag closes: ``close`` finishes the bag with
    the chunks before it (in the room kept), then raises, so the run says its bag is short."""
    instants = _instants(100, seed=9)
    bag = Bag(tmp_path / 'bag', TOPICS, typestore, OFFERED_QOS, {'scene': 'full'})
    bag.write('/robot_description', 0, b'urdf')
    for stamp, row in instants:
        bag.write_instants([stamp], {topic: [row[topic]] for topic in ('/clock', '/chatter')})
    bag.write_instants([10**12], {'/clock': [b'c'], '/chatter': [b'open']})
    whole, lost = len(bag._chunk_indexes), sum(len(r) for r in bag._index.values())
    assert whole >= 1 and lost >= 2  # some chunks written, one open
    bag._file = _FillingFile(bag._file, 10)  # less than the open chunk's record
    with pytest.raises(OSError, match='No space left'):
        bag.close()
    with (tmp_path / 'bag' / 'bag.mcap').open('rb') as stream:
        summary = make_reader(stream, validate_crcs=True).get_summary()
    assert summary.statistics.chunk_count == whole
    with Reader(tmp_path / 'bag') as reader:
        assert reader.message_count == summary.statistics.message_count == (
            1 + 2 * (len(instants) + 1) - lost)
