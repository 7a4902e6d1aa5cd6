"""Byte layouts of ROS messages in CDR, computed from their ``.msg`` definitions.

``Layout`` (where each number lies; ``program``, ``read``, ``unpacker``), ``layout_for``,
``layout_of``, ``LayoutCache``. See docs/architecture.md, 'Byte layouts come from the ``.msg``
definitions'.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
import operator
import struct
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

import iceskate_native

ENCAPSULATION = b'\x00\x01\x00\x00'  # CDR, little endian, no options
HEADER = len(ENCAPSULATION)
#: numpy dtype of each numeric primitive.
PRIMITIVES = {
    'bool': '<u1', 'byte': '<u1', 'char': '<u1', 'octet': '<u1', 'uint8': '<u1',
    'int8': '<i1', 'int16': '<i2', 'uint16': '<u2', 'int32': '<i4', 'uint32': '<u4',
    'int64': '<i8', 'uint64': '<u8', 'float32': '<f4', 'float64': '<f8'}
_COUNT = struct.Struct('<I')


class LayoutError(ValueError):
    """Bytes that do not hold a message of the type, or a shape that does not fit it."""


@dataclass(frozen=True)
class Field:
    """Where the numbers of one field lie: ``count`` values of ``dtype`` from byte ``offset``
    (from the start of the message's bytes, encapsulation header included)."""

    offset: int
    dtype: np.dtype
    count: int


@dataclass(frozen=True)
class Layout:
    """The byte layout of one message of a type with given strings and sequence lengths.

    :ivar size: bytes of the message.
    :ivar fields: every numeric field by path (stamps as ``header.stamp.sec`` and ``.nanosec``).
    :ivar strings: every string by path.
    :ivar skeleton: (byte offset, bytes) of every count and string: a message whose bytes
        match them has this layout (``fits``).
    :ivar template: the message's bytes with every number 0 (what ``program`` writes into).
    """

    size: int
    fields: Mapping[str, Field]
    strings: Mapping[str, str]
    skeleton: tuple[tuple[int, bytes], ...]
    template: bytes

    def __post_init__(self) -> None:
        # the skeleton's places, taken from a message's bytes in one call (``fits``)
        places = [slice(offset, offset + len(part)) for offset, part in self.skeleton]
        parts = tuple(part for _, part in self.skeleton)
        object.__setattr__(self, '_skeleton_of', operator.itemgetter(*places, slice(0, 0)))
        object.__setattr__(self, '_skeleton_parts', (*parts, b''))

    def fits(self, data: bytes) -> bool:
        """Whether ``data`` is a message of this layout (its length up to the padding to 4
        bytes that some writers add, its counts and strings)."""
        return 0 <= len(data) - self.size < 4 and self._skeleton_of(data) == self._skeleton_parts

    def texts(self, path: str) -> list[str]:
        """The strings of the sequence or array of strings ``path``."""
        out = []
        while f'{path}.{len(out)}' in self.strings:
            out.append(self.strings[f'{path}.{len(out)}'])
        return out

    def read(self, data: bytes, path: str) -> np.ndarray:
        """The values of field ``path`` in ``data`` (a read-only view)."""
        field = self.fields[path]
        return np.frombuffer(data, field.dtype, field.count, field.offset)

    def unpacker(self, paths: Sequence[str]) -> Callable[[bytes], tuple]:
        """A function of a message's bytes giving the values of the one-number fields ``paths``
        (at least two, in this order), read in one ``struct`` call.

        :raises LayoutError: for a path that is not a one-number field.
        """
        for path in paths:
            if path not in self.fields or self.fields[path].count != 1:
                raise LayoutError(f'{path!r} is not a one-number field')
        order = sorted(range(len(paths)), key=lambda k: self.fields[paths[k]].offset)
        formats, position = ['<'], 0
        for k in order:
            field = self.fields[paths[k]]
            formats.append(f'{field.offset - position}x{_STRUCT[field.dtype.str]}')
            position = field.offset + field.dtype.itemsize
        unpack = struct.Struct(''.join(formats)).unpack_from
        back = operator.itemgetter(*(order.index(k) for k in range(len(paths))))
        return lambda data: back(unpack(data))

    def program(self, sources: Mapping[str, Sequence[tuple[int, int]]]
                ) -> iceskate_native.CdrProgram:
        """The writer of messages of this layout whose numbers come from columns of samples
        (``iceskate_native.encode_rows``, ``ControlLoop.live_messages``).

        :param sources: per numeric field path, the (column, element) of each of its numbers;
            per builtin_interfaces/Time path (e.g. ``header.stamp``), the (column, element) of
            its nanoseconds. A number not named stays 0.
        :raises LayoutError: for a path that is no such field or a wrong count of numbers.
        """
        slots: list[tuple[int, int, int, int]] = []
        for path, numbers in sources.items():
            field = self.fields.get(path)
            if field is None:
                sec, nanosec = (self.fields.get(f'{path}.{part}') for part in ('sec', 'nanosec'))
                if sec is None or nanosec is None or len(numbers) != 1:
                    raise LayoutError(f'{path!r} is neither a numeric field nor a stamp')
                slots.append((sec.offset, _STAMP_WRITE, *numbers[0]))
                continue
            write = _WRITES[field.dtype.str]
            if len(numbers) != field.count:
                raise LayoutError(f'{path!r} holds {field.count} numbers, not {len(numbers)}')
            slots += [(field.offset + k * field.dtype.itemsize, write, column, element)
                      for k, (column, element) in enumerate(numbers)]
        return iceskate_native.CdrProgram(self.template,
                                          np.array(slots, dtype=np.uint32).reshape(-1, 4))


#: ``iceskate_native.CdrProgram``'s write code of each field type it writes, and of a stamp
_WRITES = {'<f8': 0, '<i4': 1, '<u4': 2, '|u1': 3, '<f4': 5, '|i1': 6, '<i2': 7, '<u2': 8,
           '<i8': 9, '<u8': 10}
_STAMP_WRITE = 4
#: struct format of each numpy dtype of ``PRIMITIVES``
_STRUCT = {'|u1': 'B', '|i1': 'b', '<u2': 'H', '<i2': 'h', '<u4': 'I', '<i4': 'i', '<u8': 'Q',
           '<i8': 'q', '<f4': 'f', '<f8': 'd'}


def layout_of(typestore: Typestore, msgtype: str, data: bytes) -> Layout:
    """The layout of the message ``data`` (CDR bytes of a ``msgtype``).

    :raises LayoutError: for bytes that are not little-endian CDR of ``msgtype``.
    """
    if len(data) < HEADER or data[:2] != ENCAPSULATION[:2]:
        raise LayoutError('not little-endian CDR')
    walk = _Walk(typestore, data)
    walk.message(msgtype, '')
    if len(data) - walk.pos >= 4:  # up to 3: the padding some writers add
        raise LayoutError(f'{len(data) - walk.pos} bytes after the end of the message')
    return walk.layout(bytes(data[:2]) + bytes(data[2:4]))


def layout_for(typestore: Typestore, msgtype: str,
               shape: Mapping[str, int | str | Sequence[str]]) -> Layout:
    """The layout of a ``msgtype`` whose sequences, arrays of strings and strings are given by
    path in ``shape``: a length for a sequence of numbers or messages, a list for one of
    strings, a str for a string (anything not named: empty). ``template`` is then the
    message's bytes (numbers 0), as rosbags serialises it.

    :raises LayoutError: for a path of ``shape`` that is not in the message.
    """
    walk = _Walk(typestore, shape=shape)
    walk.message(msgtype, '')
    unused = set(shape) - walk.used
    if unused:
        raise LayoutError(f'{msgtype} has no field {sorted(unused)[0]!r}')
    return walk.layout(ENCAPSULATION)


class _Walk:
    """One pass over a message type's definition: offsets of every field, the skeleton, and
    the template bytes. Its counts and strings are read from a message's bytes ``data``
    (``layout_of``) or, writing, taken from a shape (``layout_for``; ``used``: its paths met)."""

    def __init__(self, typestore: Typestore, data: bytes | None = None,
                 shape: Mapping[str, int | str | Sequence[str]] | None = None) -> None:
        self.typestore, self.data, self.shape = typestore, data, shape
        self.used: set[str] = set()
        self.pos = HEADER
        self.fields: dict[str, Field] = {}
        self.strings: dict[str, str] = {}
        self.skeleton: list[tuple[int, bytes]] = []
        self.out = bytearray(ENCAPSULATION) if data is None else None

    def value(self, path: str) -> int | str | Sequence[str] | None:
        """The shape's count, string or strings at ``path`` (writing)."""
        if path in self.shape:
            self.used.add(path)
        return self.shape.get(path)

    def read_count(self, offset: int) -> int:
        """The uint32 at ``offset`` of the bytes read."""
        if offset + 4 > len(self.data):
            raise LayoutError(f'{len(self.data)} bytes end inside the message')
        return _COUNT.unpack_from(self.data, offset)[0]

    def layout(self, encapsulation: bytes) -> Layout:
        template = bytes(self.out) if self.out is not None else bytes(self.data[:self.pos])
        numbers = bytearray(template)
        for field in self.fields.values():  # the template's numbers are 0
            numbers[field.offset:field.offset + field.dtype.itemsize * field.count] = bytes(
                field.dtype.itemsize * field.count)
        return Layout(self.pos, self.fields, self.strings,
                      ((0, encapsulation[:2]), *self.skeleton), bytes(numbers))

    def align(self, size: int) -> None:
        pad = -(self.pos - HEADER) % size
        if self.out is not None:
            self.out += bytes(pad)
        self.pos += pad

    def advance(self, size: int) -> int:
        start = self.pos
        self.pos += size
        if self.out is not None:
            self.out += bytes(size)
        elif self.pos > len(self.data):
            raise LayoutError(f'{len(self.data)} bytes end inside the message')
        return start

    def count(self, path: str) -> int:
        """A sequence's or string's uint32 count at the current position."""
        self.align(4)
        start = self.pos
        if self.out is not None:
            value = self.value(path)
            count = (len(value) if isinstance(value, (list, tuple)) else int(value or 0))
            self.out += _COUNT.pack(count)
        else:
            count = self.read_count(start)
        self.pos += 4
        self.skeleton.append((start, _COUNT.pack(count)))
        return count

    def string(self, path: str, value: str | None = None) -> None:
        self.align(4)
        start = self.pos
        if self.out is not None:
            text = value if value is not None else self.value(path) or ''
            self.strings[path] = str(text)
            encoded = self.strings[path].encode() + b'\0'
            self.out += _COUNT.pack(len(encoded)) + encoded
            self.pos += 4 + len(encoded)
        else:
            size = self.read_count(start)
            end = start + 4 + size
            if end > len(self.data) or size == 0 or self.data[end - 1] != 0:
                raise LayoutError(f'string {path!r} is cut or lacks its terminating NUL')
            try:
                self.strings[path] = bytes(self.data[start + 4:end - 1]).decode()
            except UnicodeDecodeError as exc:
                raise LayoutError(f'string {path!r} is not UTF-8: {exc}') from None
            self.pos = end
        self.skeleton.append((start, bytes((self.out if self.out is not None
                                            else self.data)[start:self.pos])))

    def message(self, msgtype: str, prefix: str) -> None:
        for name, (kind, detail) in self.typestore.fielddefs[msgtype][1]:
            path = prefix + name
            if kind == Nodetype.NAME:
                self.message(detail, path + '.')
            elif kind == Nodetype.BASE:
                self.elements(detail, path, 1, array=False)
            else:  # ARRAY: (element, length); SEQUENCE: (element, bound)
                element, length = detail
                if kind == Nodetype.SEQUENCE:
                    length = self.count(path)
                self.elements(element, path, length, array=True)

    def elements(self, element: tuple, path: str, count: int, array: bool) -> None:
        """``count`` elements of type ``element`` (a BASE detail when not ``array``)."""
        if not array:
            primitive = element[0]
            if primitive == 'string':
                self.string(path)
            else:
                self.number(path, primitive, 1)
            return
        kind, detail = element
        if kind == Nodetype.NAME:
            for k in range(count):
                self.message(detail, f'{path}.{k}.')
        elif detail[0] == 'string':
            given = (self.value(path) if self.out is not None else None) or ()
            for k in range(count):
                self.string(f'{path}.{k}', given[k] if k < len(given) else None)
        else:
            self.number(path, detail[0], count)

    def number(self, path: str, primitive: str, count: int) -> None:
        dtype = np.dtype(PRIMITIVES[primitive])
        if count:
            self.align(dtype.itemsize)
        self.fields[path] = Field(self.advance(dtype.itemsize * count) if count else self.pos,
                                  dtype, count)


class LayoutCache:
    """The layouts of the messages of one type seen lately (a message of a known layout costs
    a comparison of its counts and strings; another one walk of its bytes), each with what
    ``prepare`` made of it (e.g. its readers).

    :param capacity: layouts kept (the least recently used goes first).
    :param prepare: made once per layout (default: nothing).
    """

    def __init__(self, typestore: Typestore, msgtype: str, capacity: int = 64,
                 prepare: Callable[[Layout], Any] = lambda layout: None) -> None:
        self.typestore, self.msgtype, self.capacity = typestore, msgtype, capacity
        self._prepare = prepare
        self._known: list[tuple[Layout, Any]] = []

    def lookup(self, data: bytes) -> tuple[Layout, Any]:
        """The layout of ``data`` and what ``prepare`` made of it.

        :raises LayoutError: for bytes that are not a message of the type.
        """
        for k, entry in enumerate(self._known):
            if entry[0].fits(data):
                if k:
                    self._known.insert(0, self._known.pop(k))
                return entry
        layout = layout_of(self.typestore, self.msgtype, data)
        entry = (layout, self._prepare(layout))
        self._known.insert(0, entry)
        del self._known[self.capacity:]
        return entry
