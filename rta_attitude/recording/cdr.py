"""Just enough of an XCDR1 reader for the message types of a run, straight from a bag's raw bytes.

Reading the raw bytes directly is ~6x faster than mcap_ros2's generic decoder on filter_status
(hundreds of strings per message). Any surprise raises CdrError, and the caller then decodes the bag
with the generic decoder: this reader is a fast path, never the only path.
"""

from __future__ import annotations

import struct

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
NS_PER_S = 1_000_000_000


class CdrError(Exception):
    """Raw bytes that the fast reader does not handle (the generic decoder then reads the bag)."""


class Cdr:
    """Just enough of an XCDR1 reader for the four message types of a run (plain CDR, either byte order).

    Reading the raw bytes of the bag directly is ~6x faster than mcap_ros2's generic decoder on
    filter_status (hundreds of strings per message); any surprise raises CdrError.
    """

    def __init__(self, data: bytes) -> None:
        if len(data) < 4 or data[0] != 0 or data[1] not in (0, 1):
            raise CdrError("not plain CDR")
        self.buf, self.pos = data, 4
        self.order = "<" if data[1] == 1 else ">"

    def _align(self, n: int) -> None:
        self.pos += -(self.pos - 4) % n

    def u32(self) -> int:
        self._align(4)
        (v,) = struct.unpack_from(self.order + "I", self.buf, self.pos)
        self.pos += 4
        return int(v)

    def u8(self) -> int:
        v = self.buf[self.pos]
        self.pos += 1
        return v

    def string(self) -> str:
        n = self.u32()
        end = self.pos + n
        if end > len(self.buf) or (n and self.buf[end - 1] != 0):
            raise CdrError("bad string")
        text = self.buf[self.pos:end - 1].decode("utf-8") if n else ""
        self.pos = end
        return text

    def doubles(self, count: int) -> Array:
        self._align(8)
        arr = np.frombuffer(self.buf, dtype=self.order + "f8", count=count, offset=self.pos)
        self.pos += 8 * count
        return arr.astype(float)

    def header(self) -> int:
        """std_msgs/Header: the stamp in ns (frame_id skipped)."""
        sec, nanosec = struct.unpack_from(self.order + "iI", self.buf, self.pos)
        self.pos += 8
        self.string()
        return int(sec) * NS_PER_S + int(nanosec)


def read_state(c: Cdr) -> tuple[int, tuple[str, ...], Array]:
    stamp = c.header()
    names = tuple(c.string() for _ in range(c.u32()))
    return stamp, names, c.doubles(c.u32())


def read_vector(c: Cdr) -> tuple[int, Array]:
    stamp = c.header()
    return stamp, c.doubles(3)


def read_diagnostics(c: Cdr) -> tuple[int, dict[str, dict[str, str]]]:
    """DiagnosticArray; the KeyValue loop (most of a filter_status) is inlined for speed."""
    stamp = c.header()
    buf, order = c.buf, c.order
    u32 = struct.Struct(order + "I").unpack_from
    size = len(buf)
    out: dict[str, dict[str, str]] = {}
    for _ in range(c.u32()):
        c.u8()  # level
        name = c.string()
        c.string()  # message
        c.string()  # hardware_id
        count = c.u32()
        pos = c.pos
        values: dict[str, str] = {}
        for _ in range(count):  # key, value: uint32 length (incl. NUL), bytes, NUL; lengths 4-aligned
            pos += -(pos - 4) % 4
            (n,) = u32(buf, pos)
            key_end = pos + 4 + n
            pos = key_end + (-(key_end - 4) % 4)
            (m,) = u32(buf, pos)
            value_end = pos + 4 + m
            if not n or not m or value_end > size or buf[key_end - 1] or buf[value_end - 1]:
                raise CdrError("bad string")
            values[buf[key_end - n:key_end - 1].decode()] = buf[pos + 4:value_end - 1].decode()
            pos = value_end
        c.pos = pos
        out[name] = values
    return stamp, out


__all__ = ["Cdr", "CdrError", "read_diagnostics", "read_state", "read_vector"]
