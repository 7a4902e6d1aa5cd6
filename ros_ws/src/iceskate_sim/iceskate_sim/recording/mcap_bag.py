"""A rosbag2 bag (MCAP storage) written many messages at a time with the ``mcap`` records.

``Bag`` (``write_instants``: the messages of many control instants in one call; ``close``).
See docs/architecture.md, 'Bags'.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
import errno
import pathlib
import struct
from typing import Any, BinaryIO
import zlib

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from rosbags.typesys.store import Typestore
import yaml
import zstandard

from iceskate_sim.disk import Room

MAGIC = b'\x89MCAP0\r\n'
#: A chunk is written once its records pass this many bytes (as rosbag2's MCAP storage does).
CHUNK_BYTES = 2**20
#: How a chunk's records are compressed: zstd at level 1 (a bag 3.5 times smaller, ~5 ms a MiB
#: in the writer process; every MCAP reader takes it).
COMPRESSION = 'zstd'
#: MCAP Message record: opcode, record length, channel id, sequence, log and publish time [ns].
_MESSAGE = struct.Struct('<BQHIQQ')
_MESSAGE_FIELDS = _MESSAGE.size - 9  # the record's own fields before its data
ROS_DISTRO = 'jazzy'
#: Disk [bytes] the bag keeps from its start (``.summary.room`` in its folder) for its summary,
#: footer and ``metadata.yaml``, grown by ``CHUNK_ROOM`` with each chunk (its index), given back
#: when it closes: on a full disk the bag still closes, with the chunks written whole.
SUMMARY_ROOM = 256 << 10
CHUNK_ROOM = 256


@dataclass
class _Topic:
    """A recorded topic: its MCAP channel and what ``metadata.yaml`` says of it."""

    channel: int
    msgtype: str
    digest: str  # RIHS01 hash of the message type
    qos: list[dict[str, Any]]  # offered QoS profiles, rosbag2's YAML form
    count: int = 0


class Bag:
    """Write the rosbag2 bag ``path`` (a new folder holding ``<name>.mcap`` and ``metadata.yaml``).

    A chunk that cannot be written whole (a full disk) is cut off, its messages lost, and the
    error raised; ``close`` then finishes the bag with the chunks before it (and their counts
    and times) in the room kept for it.

    :param topics: topic -> message type, in channel order.
    :param typestore: the message definitions (schemas and type hashes).
    :param offered_qos: topic -> its offered QoS profiles (rosbag2's YAML form); none elsewhere.
    :param custom_data: the metadata's ``custom_data`` (strings).
    :raises FileExistsError: if ``path`` exists.
    """

    def __init__(self, path: pathlib.Path, topics: Mapping[str, str], typestore: Typestore,
                 offered_qos: Mapping[str, list[dict[str, Any]]],
                 custom_data: Mapping[str, str]) -> None:
        self.path = path
        path.mkdir(parents=True, exist_ok=False)
        # twice the custom data: in the mcap file and in metadata.yaml
        self._room_base = SUMMARY_ROOM + 2 * sum(len(k) + len(v) for k, v in custom_data.items())
        self._room = Room(path / '.summary.room', self._room_base)
        # unbuffered: what ``_put`` wrote is on the file, and a full disk raises there
        self._file: BinaryIO = (path / f'{path.name}.mcap').open('xb', buffering=0)
        self._custom_data = dict(custom_data)
        self._compressor = zstandard.ZstdCompressor(level=1)
        self._schemas: dict[str, Schema] = {}
        self._channels: list[Channel] = []
        self.topics: dict[str, _Topic] = {}
        for topic, msgtype in topics.items():
            if msgtype not in self._schemas:
                msgdef, _ = typestore.generate_msgdef(msgtype, ros_version=2)
                self._schemas[msgtype] = Schema(id=len(self._schemas) + 1, data=msgdef.encode(),
                                                encoding='ros2msg', name=msgtype)
            qos = list(offered_qos.get(topic, ()))
            self.topics[topic] = _Topic(len(self._channels) + 1, msgtype,
                                        typestore.hash_rihs01(msgtype), qos)
            self._channels.append(Channel(
                id=len(self._channels) + 1, topic=topic, message_encoding='cdr',
                schema_id=self._schemas[msgtype].id,
                metadata={'offered_qos_profiles': yaml.safe_dump(qos, sort_keys=False).strip()
                          if qos else ''}))
        self._put(MAGIC)
        self._write([Header(profile='ros2', library=f'iceskate-{ROS_DISTRO}'),
                     *self._schemas.values(),
                     *self._channels])
        self._parts: list[bytes] = []  # the open chunk's records
        self._size = 0  # their bytes
        self._index: dict[int, list[tuple[int, int]]] = defaultdict(list)
        self._chunk_times = [2**64 - 1, 0]
        self._times = [2**64 - 1, 0]  # of the chunks written
        self._chunk_indexes: list[ChunkIndex] = []
        self._written = self._file.tell()  # the end of the last chunk written whole

    def write(self, topic: str, stamp: int, data: bytes) -> None:
        """Write one message of ``topic`` stamped ``stamp`` [ns]."""
        self.write_instants([stamp], {topic: [data]})

    def write_instants(self, stamps: Sequence[int],
                       messages: Mapping[str, Sequence[bytes | None]]) -> None:
        """Write the messages of consecutive instants: at each stamp [ns] of ``stamps``, one
        message of every topic of ``messages`` (topic -> its data at each instant, None: no
        message at that instant), in that order.

        :raises KeyError: for a topic the bag does not have.
        """
        channels = [(self.topics[topic].channel, data) for topic, data in messages.items()]
        parts, index, size = self._parts, self._index, self._size
        first = 0  # the first instant of this call in the open chunk
        for k, stamp in enumerate(stamps):
            for channel, data in channels:
                if data[k] is None:
                    continue
                index[channel].append((stamp, size))
                parts += (_MESSAGE.pack(0x05, _MESSAGE_FIELDS + len(data[k]), channel, 0, stamp,
                                        stamp), data[k])
                size += _MESSAGE.size + len(data[k])
            if size >= CHUNK_BYTES:
                self._widen(self._chunk_times, stamps[first:k + 1])
                self._close_chunk()
                parts, index, size, first = self._parts, self._index, 0, k + 1
        self._size = size
        self._widen(self._chunk_times, stamps[first:])

    @staticmethod
    def _widen(times: list[int], stamps: Sequence[int]) -> None:
        """Widen the interval ``times`` [first, last] (ns) to hold ``stamps``."""
        if len(stamps):
            times[0], times[1] = min(times[0], min(stamps)), max(times[1], max(stamps))

    def _close_chunk(self) -> None:
        """Write the open chunk and its message indexes (whole, or cut off from the file and
        the error raised)."""
        if not self._parts:
            return
        try:
            self._write_chunk()
        except OSError:
            self._file.truncate(self._written)
            self._file.seek(self._written)
            raise
        finally:  # written or lost
            self._parts, self._size, self._index = [], 0, defaultdict(list)
            self._chunk_times = [2**64 - 1, 0]
        self._written = self._file.tell()

    def _write_chunk(self) -> None:
        """Write the open chunk, its message indexes, and count it."""
        raw = b''.join(self._parts)
        data = self._compressor.compress(raw)
        start = self._file.tell()
        start_time, end_time = self._chunk_times
        self._write([Chunk(compression=COMPRESSION, data=data, message_start_time=start_time,
                           message_end_time=end_time, uncompressed_crc=zlib.crc32(raw),
                           uncompressed_size=len(raw))])
        chunk_end = self._file.tell()
        offsets = {}
        for channel, records in sorted(self._index.items()):
            offsets[channel] = self._file.tell()
            self._write([MessageIndex(channel_id=channel, records=records)])
        self._room.grow(self._room_base + CHUNK_ROOM * (len(self._chunk_indexes) + 1))
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=start_time, message_end_time=end_time, chunk_start_offset=start,
            chunk_length=chunk_end - start, message_index_offsets=offsets,
            message_index_length=self._file.tell() - chunk_end, compression=COMPRESSION,
            compressed_size=len(data), uncompressed_size=len(raw)))
        self._widen(self._times, self._chunk_times)
        channels = {channel: len(records) for channel, records in self._index.items()}
        for topic in self.topics.values():
            topic.count += channels.get(topic.channel, 0)

    def close(self) -> None:
        """Finish the file (summary, footer) and write ``metadata.yaml`` (idempotent).

        :raises OSError: when the open chunk could not be written (a full disk): the bag is
            then finished with the chunks before it.
        """
        if self._file.closed:
            return
        lost: OSError | None = None
        try:
            self._close_chunk()
        except OSError as exc:  # its messages are lost; the bag closes with the others
            lost = exc
        self._room.release()  # the room for what follows
        try:
            self._finish_file()
        finally:
            self._file.close()
        text = yaml.safe_dump({'rosbag2_bagfile_information': self._metadata()},
                              sort_keys=False)
        staged = self.path / 'metadata.yaml.tmp'
        staged.write_text(text, encoding='utf-8')
        staged.replace(self.path / 'metadata.yaml')
        if lost is not None:
            raise lost

    def _finish_file(self) -> None:
        """Write the metadata, the summary and the footer."""
        info = self._metadata()
        metadata_start = self._file.tell()
        self._write([Metadata(name='rosbag2', metadata={
            'serialized_metadata': yaml.safe_dump(info, sort_keys=False).strip(),
            'ros_distro': ROS_DISTRO})])
        metadata_index = MetadataIndex(offset=metadata_start, name='rosbag2',
                                       length=self._file.tell() - metadata_start)
        self._write([DataEnd(data_section_crc=0)])
        counts = {topic.channel: topic.count for topic in self.topics.values()}
        empty = not any(counts.values())
        statistics = Statistics(
            message_count=sum(counts.values()), schema_count=len(self._schemas),
            channel_count=len(self._channels), attachment_count=0, metadata_count=1,
            chunk_count=len(self._chunk_indexes), channel_message_counts=counts,
            message_start_time=0 if empty else self._times[0],
            message_end_time=0 if empty else self._times[1])
        summary_start = self._file.tell()
        groups = [(Opcode.SCHEMA, list(self._schemas.values())),
                  (Opcode.CHANNEL, self._channels), (Opcode.STATISTICS, [statistics]),
                  (Opcode.CHUNK_INDEX, self._chunk_indexes),
                  (Opcode.METADATA_INDEX, [metadata_index])]
        offsets = []
        for opcode, records in groups:
            if records:
                start = self._file.tell()
                self._write(records)
                offsets.append(SummaryOffset(group_opcode=opcode, group_start=start,
                                             group_length=self._file.tell() - start))
        summary_offset_start = self._file.tell()
        self._write([*offsets, Footer(summary_start=summary_start,
                                      summary_offset_start=summary_offset_start,
                                      summary_crc=0)])
        self._put(MAGIC)

    def _metadata(self) -> dict[str, Any]:
        """rosbag2's bag information (``metadata.yaml``, format version 9)."""
        count = sum(topic.count for topic in self.topics.values())
        start = self._times[0] if count else 0
        duration = self._times[1] - start if count else 0
        name = f'{self.path.name}.mcap'
        return {
            'version': 9, 'storage_identifier': 'mcap', 'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start}, 'message_count': count,
            'topics_with_message_count': [
                {'topic_metadata': {'name': name_, 'type': topic.msgtype,
                                    'serialization_format': 'cdr',
                                    'offered_qos_profiles': topic.qos,
                                    'type_description_hash': topic.digest},
                 'message_count': topic.count}
                for name_, topic in self.topics.items()],
            'compression_format': '', 'compression_mode': '', 'relative_file_paths': [name],
            'files': [{'path': name, 'starting_time': {'nanoseconds_since_epoch': start},
                       'duration': {'nanoseconds': duration}, 'message_count': count}],
            'custom_data': self._custom_data, 'ros_distro': ROS_DISTRO}

    def _write(self, records: list[Any]) -> None:
        """Write MCAP records at the end of the file."""
        builder = RecordBuilder()
        for record in records:
            record.write(builder)
        self._put(builder.end())

    def _put(self, data: bytes) -> None:
        """Write ``data`` at the end of the file, all of it (a write may take only part)."""
        view = memoryview(data)
        while view:
            taken = self._file.write(view)
            if not taken:
                raise OSError(errno.ENOSPC, 'no byte written')
            view = view[taken:]
