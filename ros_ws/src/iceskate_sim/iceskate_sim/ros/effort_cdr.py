"""``EffortCommand`` as CDR bytes, both ways, without message objects (the lockstep's hot path).

The simulator takes ``effort_commands`` raw and the controller nodes publish them raw: rclpy's
message objects cost 15-21 us to deserialize and 10-35 us more to convert, per command and
period, on the lockstep's critical path. A controller's command has the same layout at every
instant (its names, sources and array lengths do not change), so:

* ``CommandDecoder`` reads one sender's first message field by field (``read_effort_command``)
  and checks it with ``command_from_message``, which names any problem; it then keeps the
  message's *skeleton* (the bytes other than the stamp and the float64 values). A later message
  with the same skeleton is read from the known offsets (its values checked: finite, gains
  >= 0) into ``CommandValues``, views of its bytes that the native loop takes as they are; any
  other goes the checked way again.
* ``CommandEncoder`` writes a controller's command into the bytes of its previous one when the
  layout is the same (stamp and values only), else serializes it whole.

Both follow the XCDR1 little-endian encoding rclpy and Fast DDS use (``cdr``), so the bytes
equal ``rclpy.serialization.serialize_message``'s up to its padding; a new
layout is serialized by rosbags (the bag's codec).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
import struct
from types import SimpleNamespace
from typing import Any

import numpy as np
from rosbags.typesys.store import Typestore

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import CommandValues, ControllerCommand, all_finite
from iceskate_sim.model.robot import COORDINATE_NAMES
from iceskate_sim.model.stamps import ns_to_sec_nanosec
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.ros.cdr import HEADER, STAMP, CdrReader
from iceskate_sim.ros.conversions import command_fields, command_from_message

#: The float64 sequences of an EffortCommand, in order.
ARRAYS = ('effort', 'stiffness', 'damping', 'position_reference', 'source_efforts',
          'head_target')
_TYPE = 'iceskate_interfaces/msg/EffortCommand'


@dataclass(frozen=True)
class _Layout:
    """Where one EffortCommand's values lie: ``arrays`` (byte offset, count) per ``ARRAYS``
    field, the message's length and its skeleton (see the module docstring) as (byte offset,
    bytes) parts."""

    arrays: tuple[tuple[int, int], ...]
    size: int
    skeleton: tuple[tuple[int, bytes], ...]

    def fits(self, data: bytes) -> bool:
        """Whether ``data`` has this layout (its skeleton's bytes)."""
        return len(data) >= self.size and all(
            data[offset:offset + len(part)] == part for offset, part in self.skeleton)

    @cached_property
    def slots(self) -> tuple[np.ndarray, tuple[slice, ...], slice]:
        """The value slots as float64 indices from byte ``HEADER`` on (the arrays are aligned
        there): all of them, each array's, and the gains' (stiffness, damping) among all."""
        starts = [((offset - HEADER) // 8, count) for offset, count in self.arrays]
        every = np.concatenate([np.arange(start, start + count) for start, count in starts])
        effort, stiffness, damping = (count for _, count in starts[:3])
        return (every, tuple(slice(start, start + count) for start, count in starts),
                slice(effort, effort + stiffness + damping))


def read_effort_command(data: bytes) -> tuple[SimpleNamespace, _Layout]:
    """An EffortCommand's CDR bytes as an object with its fields (float64 arrays as numpy
    copies, ``stamp_ns``), and its layout.

    :raises SimulationError: for bytes that are not an EffortCommand.
    """
    try:
        reader = CdrReader(data)
        sec, nanosec = STAMP.unpack_from(data, reader.take(STAMP.size))
        fields: dict[str, Any] = {'frame_id': reader.string(), 'source': reader.string(),
                                  'joint_names': reader.strings()}
        arrays = [reader.doubles() for _ in range(4)]
        fields['source_names'] = reader.strings()
        arrays += [reader.doubles() for _ in range(2)]
    except (ValueError, UnicodeDecodeError, struct.error) as exc:
        raise SimulationError(f'undecodable effort_commands message ({len(data)} bytes): '
                              f'{exc}') from None
    for name, (offset, count) in zip(ARRAYS, arrays, strict=True):
        fields[name] = np.frombuffer(data, '<f8', count, offset).copy()
    skeleton, start = [], HEADER + STAMP.size
    for offset, count in [*arrays, (reader.pos, 0)]:
        if offset > start:
            skeleton.append((start, bytes(data[start:offset])))
        start = max(start, offset + 8 * count)
    message = SimpleNamespace(stamp_ns=sec * 1_000_000_000 + nanosec, **fields)
    return message, _Layout(tuple(arrays), reader.pos, tuple(skeleton))


class CommandDecoder:
    """``effort_commands`` CDR bytes -> (source, stamp [ns], command), every message checked
    as ``command_from_message`` checks it (see the module docstring)."""

    def __init__(self) -> None:
        #: per source: its last checked message's layout and the names that go with it
        self._known: dict[str, tuple[_Layout, tuple[str, ...]]] = {}

    def decode(self, data: bytes) -> tuple[str, int, ControllerCommand]:
        """The sender, stamp and ControllerCommand of one message.

        :raises SimulationError: naming the problem (and the source, once it is readable).
        """
        source, stamp_ns, values = self.decode_values(data)
        return source, stamp_ns, values.command()

    def decode_values(self, data: bytes) -> tuple[str, int, CommandValues]:
        """The sender, stamp and command values of one message (views of ``data`` when its
        layout is known).

        :raises SimulationError: naming the problem (and the source, once it is readable).
        """
        data = bytes(data)
        for source, (layout, sources) in self._known.items():  # the skeleton names the source
            if layout.fits(data):
                values = self._values(data, layout, sources)
                if values is not None:
                    sec, nanosec = STAMP.unpack_from(data, HEADER)
                    return source, sec * 1_000_000_000 + nanosec, values
                break
        message, layout = read_effort_command(data)
        values = CommandValues.of(command_from_message(message))
        if message.joint_names == list(COORDINATE_NAMES):  # the layout the fast way assumes
            self._known[message.source] = (layout, tuple(message.source_names))
        return message.source, message.stamp_ns, values

    @staticmethod
    def _values(data: bytes, layout: _Layout, sources: tuple[str, ...]) -> CommandValues | None:
        """The values in ``data`` (all 18 names in order, as checked before); None when a
        value is not finite or a gain negative (the checked way then says which)."""
        every, arrays, gains = layout.slots
        doubles = np.frombuffer(data, '<f8', (layout.size - HEADER) // 8, HEADER)
        values = doubles[every]
        if not all_finite(values) or (gains.stop > gains.start
                                      and min(values[gains].tolist()) < 0.0):
            return None
        return CommandValues(*(doubles[array] for array in arrays), sources)


class CommandEncoder:
    """A controller's ``CommandValues`` -> its ``effort_commands`` CDR bytes (see the module
    docstring); ``source``: the controller's name; ``typestore`` serializes a new layout
    (default: ``make_typestore()``)."""

    def __init__(self, source: str, typestore: Typestore | None = None) -> None:
        self.source = source
        self._typestore = typestore or make_typestore()
        self._last: tuple[tuple[Any, ...], _Layout, bytearray] | None = None

    def encode(self, values: CommandValues, stamp_ns: int) -> bytes:
        """The message of the command ``values`` to the state stamped ``stamp_ns``."""
        arrays = values[:6]
        shape = (values.sources, *(x.size for x in arrays))
        if self._last is None or self._last[0] != shape:
            data = bytearray(self._serialize(command_fields(values.command())))
            self._last = (shape, read_effort_command(bytes(data))[1], data)
        _, layout, data = self._last
        STAMP.pack_into(data, HEADER, *ns_to_sec_nanosec(stamp_ns))
        for (offset, count), x in zip(layout.arrays, arrays, strict=True):
            data[offset:offset + 8 * count] = x.astype('<f8', copy=False).tobytes()
        return bytes(data)

    def _serialize(self, fields: dict[str, Any]) -> bytes:
        """The CDR bytes (rosbags' serializer) of this controller's EffortCommand with
        ``fields`` (stamp 0, empty frame id)."""
        types = self._typestore.types
        header = types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=0, nanosec=0), frame_id='')
        values = {key: np.frombuffer(value, dtype=np.float64) if key in ARRAYS else list(value)
                  for key, value in fields.items()}
        message = types[_TYPE](header=header, source=self.source, **values)
        return bytes(self._typestore.serialize_cdr(message, _TYPE))
