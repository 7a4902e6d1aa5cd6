"""Reading CDR bytes without message objects: the XCDR1 little-endian encoding rclpy and Fast
DDS use (a 4-byte encapsulation header, alignment counted from the end of it, strings with their
NUL, sequences with a uint32 count). ``effort_cdr`` and ``gait_state_cdr`` read the lockstep's
messages with it.
"""

from __future__ import annotations

import struct

ENCAPSULATION = b'\x00\x01\x00\x00'  # CDR, little endian
HEADER = len(ENCAPSULATION)
STAMP = struct.Struct('<iI')  # builtin_interfaces/Time: sec, nanosec
_COUNT = struct.Struct('<I')


class CdrReader:
    """Walks the payload of a CDR message (offsets from the start of the bytes).

    :raises ValueError: for bytes that are not little-endian CDR, or that end inside a field.
    """

    def __init__(self, data: bytes) -> None:
        if len(data) < HEADER or data[:2] != ENCAPSULATION[:2]:
            raise ValueError('not little-endian CDR')
        self.data, self.pos = data, HEADER

    def align(self, size: int) -> None:
        """Step to the next multiple of ``size`` bytes (a primitive of that size)."""
        self.pos += -(self.pos - HEADER) % size

    def take(self, size: int) -> int:
        """Offset of the next ``size`` bytes, which it steps over."""
        start = self.pos
        self.pos += size
        if self.pos > len(self.data):
            raise ValueError(f'{len(self.data)} bytes end inside the message')
        return start

    def unpack(self, fmt: struct.Struct, alignment: int) -> tuple:
        """The next fields of ``fmt``, aligned to ``alignment`` bytes first (inlined: the
        readers call it per field)."""
        start = self.pos + -(self.pos - HEADER) % alignment
        self.pos = start + fmt.size
        if self.pos > len(self.data):
            raise ValueError(f'{len(self.data)} bytes end inside the message')
        return fmt.unpack_from(self.data, start)

    def count(self) -> int:
        """A sequence's or string's length."""
        return self.unpack(_COUNT, 4)[0]

    def string(self) -> str:
        size = self.count()
        start = self.take(size)
        if size == 0 or self.data[start + size - 1] != 0:
            raise ValueError('a string without its terminating NUL')
        return bytes(self.data[start:start + size - 1]).decode('utf-8')

    def skip_string(self) -> None:
        """Step over a string."""
        self.take(self.unpack(_COUNT, 4)[0])

    def strings(self) -> list[str]:
        return [self.string() for _ in range(self.count())]

    def doubles(self) -> tuple[int, int]:
        """(byte offset, count) of a float64 sequence."""
        count = self.unpack(_COUNT, 4)[0]
        if count:
            self.align(8)
        return self.take(8 * count), count
