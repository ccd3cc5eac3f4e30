"""LOCALIZE_SEGMENTS (docs/protocol.md 5.5, revision 3) at the wire level, and the parameters
digest.

Segments are kept quantised as on the wire (i16 point offsets in steps of 2^e m, ESF as u16
mantissas of 2^f), so decoded frames re-encode byte for byte; .points and .esf give the values
the server sees. Making segments (ground removal, segmentation, descriptors, quantisation) is
the C++ vehicle library's job (vehicle/segment_query.h); this module does not re-implement it.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import ClassVar, List, Optional, Tuple

import numpy as np

from ._wire import Reader, Writer, all_finite
from .errors import DecodeError, DecodeStatus
from ._constants import MessageType
from .localize import RequestHead, _empty_newest_points, get_request_head, put_newest_points, put_request_head
from .pose import Pose

SEGMENTS_FLAG_HAS_PRIOR = 1 << 0
SEGMENTS_FLAG_ESF = 1 << 1  # every segment carries its ESF histogram
SEGMENTS_FLAG_REFUSAL_CODE = 1 << 2  # revision 5, as LOCALIZE's FLAG_REFUSAL_CODE
SEGMENTS_FLAG_DETAIL = 1 << 3  # revision 6, as LOCALIZE's FLAG_DETAIL
SEGMENTS_FLAG_NEWEST_SCANS = 1 << 4  # revision 10, as LOCALIZE's FLAG_NEWEST_SCANS
# Revision 11: track on the surface layer (docs/protocol.md 5.5); needs bits 0 and 4, and the
# segments may then carry no points.
SEGMENTS_FLAG_TRACK = 1 << 5
KNOWN_SEGMENTS_FLAGS = (SEGMENTS_FLAG_HAS_PRIOR | SEGMENTS_FLAG_ESF | SEGMENTS_FLAG_REFUSAL_CODE | SEGMENTS_FLAG_DETAIL
                        | SEGMENTS_FLAG_NEWEST_SCANS | SEGMENTS_FLAG_TRACK)
SEGMENTS_FIXED_BYTES = 156
SEGMENT_BYTES = 45  # centroid, 7 eigen features, point count, step exponent
EIGEN_FEATURES = 7
ESF_BINS = 640
ESF_BYTES = 1 + 2 * ESF_BINS
POINT_EXPONENT_RANGE = (-16, 10)
ESF_EXPONENT_RANGE = (-64, 0)
SEGMENT_CODE_VERSION = 1  # core kSegmentCodeVersion: part of the digest


def segments_digest(parameters_json: str, code_version: int = SEGMENT_CODE_VERSION) -> int:
    """FNV-1a 64 over b"segmatch-segments/", the code version (u32 LE) and INFO_REPLY's
    parameters JSON byte for byte (docs/protocol.md 5.5)."""
    h = 0xCBF29CE484222325
    for b in b"segmatch-segments/" + struct.pack("<I", code_version) + parameters_json.encode("utf-8", "surrogateescape"):
        h = ((h ^ b) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


@dataclass(eq=False)
class WireSegment:
    """One segment as sent: f32 centroid and eigenvalue features, points as i16 offsets from the
    centroid in steps of 2^step_exponent m, ESF (with SEGMENTS_FLAG_ESF) as u16 mantissas."""

    centroid: Tuple[float, float, float]
    eigen: Tuple[float, ...]
    step_exponent: int
    offsets: np.ndarray  # int16 (n, 3)
    esf_exponent: Optional[int] = None
    esf_mantissas: Optional[np.ndarray] = None  # uint16 (640,)

    @property
    def points(self) -> np.ndarray:
        """float32 (n, 3), local frame: centroid + offset * 2^e in float, as the C++ decoder."""
        step = np.float32(math.ldexp(1.0, self.step_exponent))
        return np.asarray(self.centroid, dtype=np.float32) + self.offsets.astype(np.float32) * step

    @property
    def esf(self) -> Optional[np.ndarray]:
        if self.esf_mantissas is None:
            return None
        return self.esf_mantissas.astype(np.float32) * np.float32(math.ldexp(1.0, self.esf_exponent))


@dataclass(eq=False)
class LocalizeSegments(RequestHead):
    """LOCALIZE_SEGMENTS: the head (as Localize's), then parameters_digest =
    segments_digest(JSON) and the segments; with SEGMENTS_FLAG_NEWEST_SCANS (revision 10) the
    vehicle's newest scans follow: float32 (K, 3)."""

    TYPE: ClassVar[MessageType] = MessageType.LOCALIZE_SEGMENTS
    parameters_digest: int = 0
    segments: List[WireSegment] = field(default_factory=list)
    newest_points: np.ndarray = field(default_factory=_empty_newest_points)  # sent only with the flag

    def _put(self, w: Writer) -> None:
        esf = bool(self.flags & SEGMENTS_FLAG_ESF)
        put_request_head(w, self)
        w.f64(self.prior_heading_tolerance_deg)
        w.u64(self.parameters_digest)
        w.u32(len(self.segments))
        w.u32(sum(len(s.offsets) for s in self.segments))
        for s in self.segments:
            for v in tuple(s.centroid) + tuple(s.eigen):
                w.f32(v)
            w.u32(len(s.offsets))
            w.i8(s.step_exponent)
            if esf:
                if s.esf_mantissas is None:
                    raise ValueError("SEGMENTS_FLAG_ESF is set but a segment has no ESF")
                w.i8(s.esf_exponent)
                w.array(s.esf_mantissas, "<u2")
            w.array(s.offsets, "<i2")
        if self.flags & SEGMENTS_FLAG_NEWEST_SCANS:  # revision 10
            put_newest_points(w, self.newest_points)

    @classmethod
    def _get(cls, r: Reader) -> "LocalizeSegments":
        payload, size = r.data, r.remaining()
        if size < SEGMENTS_FIXED_BYTES:
            raise DecodeError(DecodeStatus.TRUNCATED)
        head, head_status = get_request_head(r)
        m = cls(**head)
        m.prior_heading_tolerance_deg, m.parameters_digest = r.f64(), r.u64()
        count, total_points = r.u32(), r.u32()
        if m.flags & ~KNOWN_SEGMENTS_FLAGS:
            raise DecodeError(DecodeStatus.BAD_FIELD, f"unknown flag bits 0x{m.flags & ~KNOWN_SEGMENTS_FLAGS:x}")
        track_needs = SEGMENTS_FLAG_HAS_PRIOR | SEGMENTS_FLAG_NEWEST_SCANS
        if m.flags & SEGMENTS_FLAG_TRACK and m.flags & track_needs != track_needs:
            raise DecodeError(DecodeStatus.BAD_FIELD, "the track bit needs a prior and the newest scans")
        esf = bool(m.flags & SEGMENTS_FLAG_ESF)
        fixed = SEGMENT_BYTES + (ESF_BYTES if esf else 0)
        end = SEGMENTS_FIXED_BYTES + count * fixed + total_points * 6
        newest = 0
        if m.flags & SEGMENTS_FLAG_NEWEST_SCANS:  # revision 10: the newest scans' count and points follow
            if end + 4 > size:
                raise DecodeError(DecodeStatus.BAD_POINT_COUNT, f"{count} segments, {total_points} points in {size} bytes")
            newest = struct.unpack_from("<I", payload, end)[0]
            if end + 4 + newest * 12 != size:
                raise DecodeError(DecodeStatus.BAD_POINT_COUNT, f"{newest} newest points in {size - end - 4} bytes")
        elif end != size:
            raise DecodeError(DecodeStatus.BAD_POINT_COUNT, f"{count} segments, {total_points} points in {size} bytes")
        if not _counts_add_up(payload, end, count, total_points, fixed):
            raise DecodeError(DecodeStatus.BAD_POINT_COUNT, f"{count} segments, {total_points} points in {size} bytes")
        if head_status:
            raise DecodeError(head_status, "sensor pose or prior")
        if not (math.isfinite(m.prior_radius_m) and math.isfinite(m.prior_heading_tolerance_deg)):
            raise DecodeError(DecodeStatus.NON_FINITE, "prior radius or heading tolerance")
        if m.prior_radius_m < 0 or m.prior_heading_tolerance_deg < 0:
            raise DecodeError(DecodeStatus.BAD_FIELD, "negative prior radius or heading tolerance")
        m.segments = [_get_segment(r, esf) for _ in range(count)]
        if m.flags & SEGMENTS_FLAG_NEWEST_SCANS:
            r.u32()  # the count, read above
            m.newest_points = r.array("<f4", newest * 3).reshape(newest, 3)
            if not np.all(np.isfinite(m.newest_points)):
                raise DecodeError(DecodeStatus.NON_FINITE, "newest point")
        r.finish()
        return m


def _counts_add_up(payload, size: int, count: int, total_points: int, fixed: int) -> bool:
    """The segments' point counts tile the payload and add up to the total (checked before any
    value is read, as the C++ decoder: a miscount must not surface as misaligned garbage)."""
    at, seen = SEGMENTS_FIXED_BYTES, 0
    for _ in range(count):
        if at + fixed > size:
            return False
        n = struct.unpack_from("<I", payload, at + 40)[0]
        seen += n
        at += fixed + n * 6
    return at == size and seen == total_points


def _get_segment(r: Reader, esf: bool) -> WireSegment:
    centroid, eigen = tuple(r.f32() for _ in range(3)), tuple(r.f32() for _ in range(EIGEN_FEATURES))
    if not all_finite(centroid + eigen):
        raise DecodeError(DecodeStatus.NON_FINITE, "segment centroid or features")
    n, step = r.u32(), r.i8()
    if not POINT_EXPONENT_RANGE[0] <= step <= POINT_EXPONENT_RANGE[1]:
        raise DecodeError(DecodeStatus.BAD_FIELD, f"point step exponent {step}")
    s = WireSegment(centroid, eigen, step, np.zeros((0, 3), dtype=np.int16))
    if esf:
        s.esf_exponent = r.i8()
        if not ESF_EXPONENT_RANGE[0] <= s.esf_exponent <= ESF_EXPONENT_RANGE[1]:
            raise DecodeError(DecodeStatus.BAD_FIELD, f"ESF exponent {s.esf_exponent}")
        s.esf_mantissas = r.array("<u2", ESF_BINS)
    s.offsets = r.array("<i2", 3 * n).reshape(n, 3)
    return s
