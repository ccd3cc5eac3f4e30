"""Little-endian byte writer and bounds-checked reader (the C++ codec's api/src/wire.h).

The reader raises DecodeError(TRUNCATED) on a short read instead of yielding zeros as the C++
one does: the message decoders read raw values first and check them afterwards, in the C++
codec's order, so the status reported for a bad frame is the one a C++ peer reports.
"""

from __future__ import annotations

import math
import struct

import numpy as np

from .errors import DecodeError, DecodeStatus

MAX_STRING_BYTES = 1 << 20  # any one string (token, reason, JSON, message): docs/protocol.md 9


class Writer:
    def __init__(self) -> None:
        self.buf = bytearray()

    def u8(self, v: int) -> None:
        self.buf += struct.pack("<B", v)

    def i8(self, v: int) -> None:
        self.buf += struct.pack("<b", v)

    def u16(self, v: int) -> None:
        self.buf += struct.pack("<H", v)

    def u32(self, v: int) -> None:
        self.buf += struct.pack("<I", v)

    def u64(self, v: int) -> None:
        self.buf += struct.pack("<Q", v)

    def f32(self, v: float) -> None:
        self.buf += struct.pack("<f", v)

    def f64(self, v: float) -> None:
        self.buf += struct.pack("<d", v)

    def f64s(self, values) -> None:
        for v in values:
            self.f64(v)

    def str(self, s: str) -> None:
        # surrogateescape: a string decoded from invalid UTF-8 goes back as the same bytes.
        b = s.encode("utf-8", "surrogateescape")
        self.u32(len(b))
        self.buf += b

    def array(self, a: np.ndarray, dtype: str) -> None:
        self.buf += np.ascontiguousarray(a, dtype=dtype).tobytes()


class Reader:
    def __init__(self, data: bytes, max_string_bytes: int = MAX_STRING_BYTES) -> None:
        self.data = memoryview(data)
        self.pos = 0
        self.max_string_bytes = max_string_bytes

    def remaining(self) -> int:
        return len(self.data) - self.pos

    def _take(self, n: int) -> memoryview:
        if n > self.remaining():
            raise DecodeError(DecodeStatus.TRUNCATED)
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def _unpack(self, fmt: str, n: int):
        return struct.unpack(fmt, self._take(n))[0]

    def u8(self) -> int:
        return self._unpack("<B", 1)

    def i8(self) -> int:
        return self._unpack("<b", 1)

    def u16(self) -> int:
        return self._unpack("<H", 2)

    def u32(self) -> int:
        return self._unpack("<I", 4)

    def u64(self) -> int:
        return self._unpack("<Q", 8)

    def f32(self) -> float:
        return self._unpack("<f", 4)

    def f64(self) -> float:
        return self._unpack("<d", 8)

    def f64s(self, n: int) -> tuple:
        return tuple(self.f64() for _ in range(n))

    def str(self) -> str:
        n = self.u32()
        if n > self.max_string_bytes:
            raise DecodeError(DecodeStatus.BAD_FIELD, f"string of {n} bytes over the limit")
        return bytes(self._take(n)).decode("utf-8", "surrogateescape")

    def array(self, dtype: str, count: int) -> np.ndarray:
        """count values of dtype, copied out of the buffer (writable, owned)."""
        size = np.dtype(dtype).itemsize * count
        return np.frombuffer(self._take(size), dtype=dtype).copy()

    def finish(self) -> None:
        if self.remaining() != 0:
            raise DecodeError(DecodeStatus.TRAILING_BYTES, f"{self.remaining()} bytes left")


def all_finite(values) -> bool:
    return all(math.isfinite(v) for v in values)
