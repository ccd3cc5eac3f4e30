"""The SGMQ wire protocol (docs/protocol.md), byte for byte as the C++ codec
(api/src/protocol.cpp, api/src/localize_codec.cpp).

Every message is a dataclass; encode(message) gives a whole frame (12-byte header + payload);
decode_frame(bytes) and decode_payload(type, payload) give the message back or raise
DecodeError with the C++ codec's DecodeStatus for the same bytes. Wire values are kept as
they are (poses as Pose: quaternion w x y z + translation, floats as Python floats, points as
float32 arrays), so a decoded frame re-encodes to the same bytes (tests/data/protocol/).

QUATERNION ORDER: w x y z on the wire; ROS uses x y z w (segmatch.pose.wxyz_from_ros_xyzw).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Optional, Tuple

from ._constants import (FLAG_DETAIL, FLAG_HAS_PRIOR, FLAG_NEWEST_SCANS, FLAG_PRIOR_HEADING, FLAG_REFUSAL_CODE, FLAG_TRACK,
                         FLAG_VOXELIZED, HEADER_BYTES, MAGIC, MAX_PAYLOAD_BYTES, REVISION, VERSION, LocalizeStatus,
                         MessageType, RefusalCode)
from ._wire import MAX_STRING_BYTES, Reader, Writer, all_finite
from .errors import DecodeError, DecodeStatus, ErrorCode, error_code
from .localize import Localize, LocalizeReply, ReplyDetail, Timings
from .pose import Pose
from .segments import LocalizeSegments, WireSegment, segments_digest


@dataclass(frozen=True)
class Header:
    type: int
    payload_bytes: int
    version: int = VERSION


def decode_header(data: bytes, max_payload_bytes: int = MAX_PAYLOAD_BYTES) -> Header:
    """The first 12 bytes of a frame. Raises DecodeError; for UNKNOWN_TYPE its .header is set so
    the caller can skip the payload, as the server does."""
    if len(data) < HEADER_BYTES:
        raise DecodeError(DecodeStatus.INCOMPLETE, f"{len(data)} of {HEADER_BYTES} header bytes")
    if bytes(data[:4]) != MAGIC:
        raise DecodeError(DecodeStatus.BAD_MAGIC, repr(bytes(data[:4])))
    r = Reader(bytes(data[4:HEADER_BYTES]))
    version, type_, size = r.u16(), r.u16(), r.u32()
    if version != VERSION:
        raise DecodeError(DecodeStatus.BAD_VERSION, f"version {version}")
    if size > max_payload_bytes:
        raise DecodeError(DecodeStatus.TOO_LARGE, f"{size} bytes > {max_payload_bytes}")
    header = Header(type_, size, version)
    if type_ not in _MESSAGES:
        err = DecodeError(DecodeStatus.UNKNOWN_TYPE, f"type 0x{type_:04x}")
        err.header = header
        raise err
    return header


# ---- messages ---------------------------------------------------------------------------------

@dataclass
class Hello:
    TYPE: ClassVar[MessageType] = MessageType.HELLO
    token: str = ""

    def _put(self, w: Writer) -> None:
        w.str(self.token)

    @classmethod
    def _get(cls, r: Reader) -> "Hello":
        return cls(r.str())


@dataclass
class HelloOk:
    TYPE: ClassVar[MessageType] = MessageType.HELLO_OK

    def _put(self, w: Writer) -> None:
        pass

    @classmethod
    def _get(cls, r: Reader) -> "HelloOk":
        return cls()


@dataclass
class Ping:
    TYPE: ClassVar[MessageType] = MessageType.PING
    nonce: int = 0

    def _put(self, w: Writer) -> None:
        w.u64(self.nonce)

    @classmethod
    def _get(cls, r: Reader) -> "Ping":
        return cls(r.u64())


@dataclass
class Pong(Ping):
    TYPE: ClassVar[MessageType] = MessageType.PONG


@dataclass
class Info:
    TYPE: ClassVar[MessageType] = MessageType.INFO

    def _put(self, w: Writer) -> None:
        pass

    @classmethod
    def _get(cls, r: Reader) -> "Info":
        return cls()


@dataclass
class InfoReply:
    """The served map. extent_*: bounding box of the segment centroids, map frame."""

    TYPE: ClassVar[MessageType] = MessageType.INFO_REPLY
    protocol_version: int = VERSION
    map_name: str = ""
    segment_count: int = 0
    extent_min: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    extent_max: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    parameters_json: str = ""  # the map's PipelineConfig (io::to_json)

    def parameters(self) -> dict:
        import json
        return json.loads(self.parameters_json)

    def _put(self, w: Writer) -> None:
        w.u16(self.protocol_version)
        w.u16(0)  # reserved
        w.str(self.map_name)
        w.u64(self.segment_count)
        w.f64s(self.extent_min)
        w.f64s(self.extent_max)
        w.str(self.parameters_json)

    @classmethod
    def _get(cls, r: Reader) -> "InfoReply":
        version, reserved = r.u16(), r.u16()
        m = cls(version, r.str(), r.u64(), r.f64s(3), r.f64s(3), r.str())
        r.finish()
        if reserved != 0:
            raise DecodeError(DecodeStatus.BAD_FIELD, "reserved field set")
        if not all_finite(m.extent_min + m.extent_max):
            raise DecodeError(DecodeStatus.NON_FINITE, "extent")
        return m


@dataclass
class Error:
    """ERROR. code: ErrorCode, or the plain int of a code this client does not know."""

    TYPE: ClassVar[MessageType] = MessageType.ERROR
    code: int = ErrorCode.INTERNAL
    message: str = ""

    def _put(self, w: Writer) -> None:
        w.u16(int(self.code))
        w.str(self.message)

    @classmethod
    def _get(cls, r: Reader) -> "Error":
        return cls(error_code(r.u16()), r.str())


# ---- frames -----------------------------------------------------------------------------------

def encode(message) -> bytes:
    """The whole frame (header + payload) of a message."""
    w = Writer()
    message._put(w)
    payload = bytes(w.buf)
    head = Writer()
    head.u16(VERSION)
    head.u16(int(message.TYPE))
    head.u32(len(payload))
    return MAGIC + bytes(head.buf) + payload


def decode_payload(message_type: int, payload: bytes, max_string_bytes: int = MAX_STRING_BYTES):
    """The message of this type from its payload (without the header)."""
    cls = _MESSAGES.get(int(message_type))
    if cls is None:
        raise DecodeError(DecodeStatus.UNKNOWN_TYPE, f"type 0x{int(message_type):04x}")
    r = Reader(payload, max_string_bytes)
    m = cls._get(r)
    r.finish()
    return m


def decode_frame(frame: bytes, expected: Optional[type] = None, max_payload_bytes: int = MAX_PAYLOAD_BYTES,
                 max_string_bytes: int = MAX_STRING_BYTES):
    """Exactly one whole frame; with `expected` (a message class) a frame of another type is
    UNKNOWN_TYPE, as the C++ decode_frame<M>."""
    header = decode_header(frame, max_payload_bytes)
    if expected is not None and header.type != expected.TYPE:
        raise DecodeError(DecodeStatus.UNKNOWN_TYPE, f"expected {expected.TYPE.name}, got type 0x{header.type:04x}")
    total = HEADER_BYTES + header.payload_bytes
    if len(frame) < total:
        raise DecodeError(DecodeStatus.INCOMPLETE, f"{len(frame)} of {total} bytes")
    if len(frame) > total:
        raise DecodeError(DecodeStatus.TRAILING_BYTES, f"{len(frame) - total} bytes after the frame")
    return decode_payload(header.type, bytes(frame[HEADER_BYTES:]), max_string_bytes)


_MESSAGES = {int(c.TYPE): c for c in (Hello, HelloOk, Ping, Pong, Info, InfoReply, Localize, LocalizeSegments,
                                      LocalizeReply, Error)}

__all__ = ["MAGIC", "VERSION", "REVISION", "HEADER_BYTES", "MAX_PAYLOAD_BYTES", "FLAG_HAS_PRIOR", "FLAG_VOXELIZED",
           "FLAG_PRIOR_HEADING", "FLAG_REFUSAL_CODE", "FLAG_DETAIL", "FLAG_NEWEST_SCANS", "FLAG_TRACK", "ReplyDetail", "RefusalCode",
           "MessageType", "LocalizeStatus", "Header", "decode_header", "Hello", "HelloOk", "Ping", "Pong", "Info",
           "InfoReply", "Localize", "LocalizeSegments", "WireSegment", "segments_digest", "Timings", "LocalizeReply",
           "Error", "encode", "decode_payload", "decode_frame", "Pose", "ErrorCode", "DecodeError", "DecodeStatus"]
