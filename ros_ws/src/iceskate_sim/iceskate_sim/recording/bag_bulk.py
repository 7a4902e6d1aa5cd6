"""Many messages into a rosbags MCAP bag at once, byte for byte as ``Writer.write`` one by one.

``rosbags.rosbag2.Writer.write`` builds each MCAP Message record in its own ``BytesIO`` (3.6 us a
message here, 22 us for the six topics of a control instant): more than the native core takes
for a whole control period, so the bag writer process fell behind the simulation. ``write_many``
appends the same records (opcode 0x05, length, channel id, sequence 0, log and publish time =
the stamp, the data) to the storage's open chunk in one join, records the same message index
entries and statistics, and closes a chunk exactly where ``write`` would (after the message that
takes it past 1 MiB). The bag is the same file (``tests/iceskate_sim/test_bag_bulk.py`` compares
them byte for byte); any other storage or per-message compression goes one by one.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
import struct

from rosbags.interfaces import Connection
from rosbags.rosbag2 import Writer
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.rosbag2.writer import CompressionMode

from iceskate_sim.errors import SimulationError

#: MCAP Message record: opcode, record length, channel id, sequence, log time, publish time.
_MESSAGE = struct.Struct('<BQHIQQ')
_FIELDS = _MESSAGE.size - 9  # the record's own fields before its data (after opcode, length)
#: rosbags' McapWriter closes its chunk after the message that makes it longer than this.
_CHUNK_BYTES = 2**20


def write_many(writer: Writer, messages: Sequence[tuple[Connection, int, bytes]]) -> None:
    """Write ``messages`` (connection, stamp [ns], serialized data) in order, as
    ``writer.write`` would one after the other.

    :raises SimulationError: for a writer that is not open or a connection it does not have.
    """
    storage = writer.storage
    if storage is None:
        raise SimulationError(f'bag {writer.path} is not open')
    if not isinstance(storage, McapWriter) or writer.compression_mode == CompressionMode.MESSAGE:
        for connection, stamp, data in messages:
            writer.write(connection, stamp, data)
        return
    used = {connection.id: connection for connection, _, _ in messages}
    if any(connection not in writer.connections for connection in used.values()):
        raise SimulationError(f'bag {writer.path}: a message of a connection it does not have')
    start, counts = 0, Counter()
    while start < len(messages):
        end, chunk_counts, first, last = _fill_chunk(storage, messages, start)
        counts.update(chunk_counts)
        writer.min_timestamp = min(writer.min_timestamp, first)
        writer.max_timestamp = max(writer.max_timestamp, last)
        start = end
    for cid, count in counts.items():
        writer.counts[cid] += count


def _fill_chunk(storage: McapWriter, messages: Sequence[tuple[Connection, int, bytes]],
                start: int) -> tuple[int, Counter, int, int]:
    """Append messages from ``start`` to the open chunk until it is full (then close it):
    (the index of the first message not written, the messages written per channel id, their
    first and last stamp [ns])."""
    chunk = storage.chunk
    offset = chunk.bio.tell()
    parts: list[bytes] = []
    end = start
    while end < len(messages) and offset <= _CHUNK_BYTES:
        connection, stamp, data = messages[end]
        chunk.msgs[connection.id].append((stamp, offset))
        parts += (_MESSAGE.pack(0x05, _FIELDS + len(data), connection.id, 0, stamp, stamp), data)
        offset += _MESSAGE.size + len(data)
        end += 1
    chunk.bio.write(b''.join(parts))
    stamps = [stamp for _, stamp, _ in messages[start:end]]
    first, last = min(stamps), max(stamps)
    storage.message_start_time = min(first, storage.message_start_time)
    storage.message_end_time = max(last, storage.message_end_time)
    chunk.message_start_time = min(first, chunk.message_start_time)
    chunk.message_end_time = max(last, chunk.message_end_time)
    counts = Counter(connection.id for connection, _, _ in messages[start:end])
    for cid, count in counts.items():
        storage.channel_stats[cid] += count
    if offset > _CHUNK_BYTES:
        storage.close_chunk()
    return end, counts, first, last
