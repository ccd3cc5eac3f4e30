"""LOCALIZE and LOCALIZE_REPLY (docs/protocol.md 5.4, 6.4), as the C++ api/src/localize_codec.cpp,
and the request head and pose fields LOCALIZE_SEGMENTS shares. Re-exported by segmatch.protocol.

QUATERNION ORDER: w x y z on the wire; ROS uses x y z w (segmatch.pose.wxyz_from_ros_xyzw).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import ClassVar, List, Optional, Tuple

import numpy as np

from ._constants import (FLAG_HAS_PRIOR, FLAG_NEWEST_SCANS, FLAG_PRIOR_HEADING, FLAG_TRACK, KNOWN_FLAGS, LOCALIZE_FIXED_BYTES, LocalizeStatus,
                         MessageType, RefusalCode)
from ._wire import Reader, Writer, all_finite
from .errors import DecodeError, DecodeStatus
from .pose import QUATERNION_NORM_TOLERANCE, Pose, unit_quaternion

# Pose fields and the request head shared with LOCALIZE_SEGMENTS (C++ codec_util.h).


def _put_quaternion(w: Writer, q) -> None:
    w.f64s(unit_quaternion(q))


def _put_pose(w: Writer, pose: Pose) -> None:
    _put_quaternion(w, pose.q_wxyz)
    w.f64s(pose.t)


def _quaternion_status(q) -> Optional[DecodeStatus]:
    if not all_finite(q):
        return DecodeStatus.NON_FINITE
    if not abs(math.sqrt(sum(v * v for v in q)) - 1.0) <= QUATERNION_NORM_TOLERANCE:
        return DecodeStatus.BAD_QUATERNION
    return None


def _pose_status(pose: Pose) -> Optional[DecodeStatus]:
    s = _quaternion_status(pose.q_wxyz)
    return s if s else (None if all_finite(pose.t) else DecodeStatus.NON_FINITE)


def put_request_head(w: Writer, m) -> None:
    """The first 132 bytes of LOCALIZE and LOCALIZE_SEGMENTS."""
    w.u64(m.request_id)
    w.u32(m.flags)
    w.f64s(m.sensor_position)
    _put_quaternion(w, m.sensor_orientation_wxyz)
    _put_pose(w, m.prior)
    w.f64(m.prior_radius_m)


def get_request_head(r: Reader) -> Tuple[dict, Optional[DecodeStatus]]:
    """Reads the head; returns its fields and the first bad value's status (checked by the
    caller after its flag and length checks, in the C++ order)."""
    head = dict(request_id=r.u64(), flags=r.u32(), sensor_position=r.f64s(3), sensor_orientation_wxyz=r.f64s(4))
    head["prior"] = Pose(r.f64s(4), r.f64s(3))
    head["prior_radius_m"] = r.f64()
    pos_status = None if all_finite(head["sensor_position"]) else DecodeStatus.NON_FINITE
    status = pos_status or _quaternion_status(head["sensor_orientation_wxyz"]) or _pose_status(head["prior"])
    return head, status


def _empty_points() -> np.ndarray:
    return np.zeros((0, 4), dtype=np.float32)


def put_newest_points(w: Writer, points) -> None:
    """The newest scans on the wire (LOCALIZE bit 5, LOCALIZE_SEGMENTS bit 4): count, then x y z f32."""
    newest = np.asarray(points)
    if newest.ndim != 2 or newest.shape[1] != 3:
        raise ValueError(f"newest_points must be an (M, 3) array, got shape {newest.shape}")
    w.u32(newest.shape[0])
    w.array(newest, "<f4")


def _empty_newest_points() -> np.ndarray:
    return np.zeros((0, 3), dtype=np.float32)


@dataclass(eq=False)
class RequestHead:
    """The fields LOCALIZE and LOCALIZE_SEGMENTS share (put_request_head / get_request_head):
    positions in the vehicle's local frame, sensor_orientation_wxyz w x y z (ROS: x y z w), the
    prior T_map_local guess used with the message's has-prior flag. The heading tolerance
    follows the head: LOCALIZE sends it only with FLAG_PRIOR_HEADING, LOCALIZE_SEGMENTS always."""

    request_id: int = 0
    flags: int = 0
    sensor_position: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    sensor_orientation_wxyz: Tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    prior: Pose = field(default_factory=Pose)
    prior_radius_m: float = 0.0
    prior_heading_tolerance_deg: float = 10.0


@dataclass(eq=False)  # eq=False: points are an array; compare encode() bytes instead
class Localize(RequestHead):
    """LOCALIZE (docs/protocol.md 5.4): the head, then points: float32 (N, 3) or (N, 4) with
    intensity; the stride on the wire is the number of columns. With FLAG_NEWEST_SCANS
    (revision 8) the vehicle's newest scans follow last: float32 (M, 3)."""

    TYPE: ClassVar[MessageType] = MessageType.LOCALIZE
    points: np.ndarray = field(default_factory=_empty_points)
    newest_points: np.ndarray = field(default_factory=_empty_newest_points)  # sent only with FLAG_NEWEST_SCANS

    def _put(self, w: Writer) -> None:
        pts = np.asarray(self.points)
        if pts.ndim != 2 or pts.shape[1] not in (3, 4):
            raise ValueError(f"points must be an (N, 3) or (N, 4) array, got shape {pts.shape}")
        put_request_head(w, self)
        w.u32(pts.shape[0])
        w.u32(pts.shape[1])
        w.array(pts, "<f4")
        if self.flags & FLAG_PRIOR_HEADING:
            w.f64(self.prior_heading_tolerance_deg)
        if self.flags & FLAG_NEWEST_SCANS:  # revision 8
            put_newest_points(w, self.newest_points)

    @classmethod
    def _get(cls, r: Reader) -> "Localize":
        size = r.remaining()
        if size < LOCALIZE_FIXED_BYTES:
            raise DecodeError(DecodeStatus.TRUNCATED)
        head, head_status = get_request_head(r)
        count, stride = r.u32(), r.u32()
        m = cls(**head)
        if m.flags & ~KNOWN_FLAGS:
            raise DecodeError(DecodeStatus.BAD_FIELD, f"unknown flag bits 0x{m.flags & ~KNOWN_FLAGS:x}")
        if m.flags & FLAG_TRACK and m.flags & (FLAG_HAS_PRIOR | FLAG_NEWEST_SCANS) != FLAG_HAS_PRIOR | FLAG_NEWEST_SCANS:
            raise DecodeError(DecodeStatus.BAD_FIELD, "the track bit needs a prior and the newest scans")
        if stride not in (3, 4):
            raise DecodeError(DecodeStatus.BAD_STRIDE, f"stride {stride}")
        trailer = 8 if m.flags & FLAG_PRIOR_HEADING else 0
        points_end = LOCALIZE_FIXED_BYTES + count * stride * 4 + trailer
        # With the newest scans (revision 8) their count follows; it is checked once read.
        if (points_end + 4 > size) if m.flags & FLAG_NEWEST_SCANS else (points_end != size):
            raise DecodeError(DecodeStatus.BAD_POINT_COUNT, f"{count} points of {stride} floats in {size} bytes")
        if head_status:
            raise DecodeError(head_status, "sensor pose or prior")
        if not math.isfinite(m.prior_radius_m):
            raise DecodeError(DecodeStatus.NON_FINITE, "prior radius")
        if m.prior_radius_m < 0:
            raise DecodeError(DecodeStatus.BAD_FIELD, "negative prior radius")
        m.points = r.array("<f4", count * stride).reshape(count, stride)
        if not np.all(np.isfinite(m.points)):
            raise DecodeError(DecodeStatus.NON_FINITE, "point")
        if trailer:
            m.prior_heading_tolerance_deg = r.f64()
            if not math.isfinite(m.prior_heading_tolerance_deg):
                raise DecodeError(DecodeStatus.NON_FINITE, "heading tolerance")
            if m.prior_heading_tolerance_deg < 0:
                raise DecodeError(DecodeStatus.BAD_FIELD, "negative heading tolerance")
        if m.flags & FLAG_NEWEST_SCANS:  # revision 8
            newest = r.u32()
            if newest * 12 != r.remaining():
                raise DecodeError(DecodeStatus.BAD_POINT_COUNT, f"{newest} newest points in {r.remaining()} bytes")
            m.newest_points = r.array("<f4", newest * 3).reshape(newest, 3)
            if not np.all(np.isfinite(m.newest_points)):
                raise DecodeError(DecodeStatus.NON_FINITE, "newest point")
        r.finish()
        return m


TIMING_NAMES = ("voxel", "ground", "segment", "describe", "retrieve", "classify", "verify", "refine", "total",
                "server_total")


@dataclass
class Timings:
    """Milliseconds per stage. total: the localizer's; server_total: frame received -> reply
    encoded, queueing included. voxel..describe are 0 for LOCALIZE_SEGMENTS."""

    voxel: float = 0.0
    ground: float = 0.0
    segment: float = 0.0
    describe: float = 0.0
    retrieve: float = 0.0
    classify: float = 0.0
    verify: float = 0.0
    refine: float = 0.0
    total: float = 0.0
    server_total: float = 0.0


@dataclass
class ReplyDetail:
    """LOCALIZE_REPLY's detail block (revision 6, docs/protocol.md 6.4), sent to a request that set
    its detail bit: how far the whole local cloud's pose and its recent window's put the sensor
    apart (the vehicle odometry's warp over the cloud), and the window's query points."""

    window_warp_m: float = 0.0
    window_warp_deg: float = 0.0
    window_points: int = 0
    # Revision 7: what answered (0 segments, 1 registration) and the upper triangle, row by row,
    # of the sensor pose's 6x6 covariance (rotation about the map axes, rad; position, m). None:
    # a revision-6 server's reply (unknown, not zero uncertainty).
    method: Optional[int] = None
    covariance_upper: Optional[List[float]] = None

    @property
    def method_name(self) -> str:
        return {None: "unknown", 0: "segments", 1: "registration", 2: "surfaces", 3: "places"}.get(self.method, "unknown")

    @property
    def covariance(self) -> Optional[np.ndarray]:
        """The 6x6 covariance (symmetric), or None when the reply has none."""
        if self.covariance_upper is None:
            return None
        c = np.zeros((6, 6))
        c[np.triu_indices(6)] = self.covariance_upper
        return c + np.triu(c, 1).T


@dataclass
class LocalizeReply:
    """LOCALIZE_REPLY (docs/protocol.md 6.4). T_map_local (4x4) maps local-frame points into the
    map; the sensor's map pose is T_map_local @ T_local_sensor. pose holds the wire values."""

    TYPE: ClassVar[MessageType] = MessageType.LOCALIZE_REPLY
    request_id: int = 0
    status: LocalizeStatus = LocalizeStatus.NOT_LOCALIZED
    reason: str = ""  # empty when localized, why not otherwise
    pose: Pose = field(default_factory=Pose)  # identity when not localized
    inliers: int = 0
    confidence: float = 0.0  # 0..1 (f32 on the wire)
    support: int = 0  # query segments that land on a map segment under the pose
    matched_segment_ids: List[int] = field(default_factory=list)  # map segment ids of the inliers
    timings: Timings = field(default_factory=Timings)
    refusal: int = 0  # revision 5: a RefusalCode when the request set its refusal-code bit, else 0
    detail: Optional[ReplyDetail] = None  # revision 6: with the request's detail bit

    @property
    def refusal_name(self) -> str:
        """The refusal code's name (RefusalCode), "UNKNOWN" for a later revision's code."""
        try:
            return RefusalCode(self.refusal).name
        except ValueError:
            return "UNKNOWN"

    @property
    def T_map_local(self) -> np.ndarray:
        return self.pose.matrix()

    @property
    def localized(self) -> bool:
        return self.status == LocalizeStatus.LOCALIZED

    def _put(self, w: Writer) -> None:
        w.u64(self.request_id)
        w.u16(int(self.status))
        w.u16(self.refusal)
        w.str(self.reason)
        _put_pose(w, self.pose)
        w.u32(self.inliers)
        w.f32(self.confidence)
        w.u32(self.support)
        w.u32(len(self.matched_segment_ids))
        for i in self.matched_segment_ids:
            w.u64(i)
        for f in fields(Timings):
            w.f32(getattr(self.timings, f.name))
        if self.detail is not None:
            d = self.detail
            estimate = d.method is not None
            w.u16(REPLY_DETAIL_ESTIMATE_BYTES if estimate else REPLY_DETAIL_BYTES)
            w.f32(d.window_warp_m)
            w.f32(d.window_warp_deg)
            w.u32(d.window_points)
            if estimate:  # revision 7
                w.u8(d.method)
                for _ in range(3):
                    w.u8(0)
                for c in d.covariance_upper or [0.0] * 21:
                    w.f32(c)

    @classmethod
    def _get(cls, r: Reader) -> "LocalizeReply":
        request_id, status, refusal, reason = r.u64(), r.u16(), r.u16(), r.str()  # any refusal code
        pose = Pose(r.f64s(4), r.f64s(3))
        inliers, confidence, support, ids = r.u32(), r.f32(), r.u32(), r.u32()
        if ids * 8 + len(TIMING_NAMES) * 4 > r.remaining():
            raise DecodeError(DecodeStatus.TRUNCATED, f"{ids} segment ids and timings in {r.remaining()} bytes")
        matched = [r.u64() for _ in range(ids)]
        timings = Timings(*(r.f32() for _ in TIMING_NAMES))
        detail = _get_detail(r) if r.remaining() > 0 else None
        pose_status = _pose_status(pose)
        if pose_status:
            raise DecodeError(pose_status, "T_map_local")
        if status > 2:
            raise DecodeError(DecodeStatus.BAD_FIELD, f"status {status}")
        if not math.isfinite(confidence):
            raise DecodeError(DecodeStatus.NON_FINITE, "confidence")
        return cls(request_id, LocalizeStatus(status), reason, pose, inliers, confidence, support, matched, timings,
                   refusal, detail)


REPLY_DETAIL_BYTES = 12  # revision 6's fields; a later revision's block is longer
REPLY_DETAIL_ESTIMATE_BYTES = 100  # with revision 7's: method and covariance


def _get_detail(r: Reader) -> ReplyDetail:
    """The detail block: its length, the fields this revision knows, the rest skipped."""
    size = r.u16()
    if size > r.remaining():
        raise DecodeError(DecodeStatus.TRUNCATED, f"detail block of {size} bytes in {r.remaining()}")
    if size < r.remaining():
        raise DecodeError(DecodeStatus.TRAILING_BYTES, f"{r.remaining() - size} bytes after the detail block")
    if size < REPLY_DETAIL_BYTES:
        raise DecodeError(DecodeStatus.BAD_FIELD, f"detail block of {size} bytes (at least {REPLY_DETAIL_BYTES})")
    d = ReplyDetail(r.f32(), r.f32(), r.u32())
    known = REPLY_DETAIL_BYTES
    if size >= REPLY_DETAIL_ESTIMATE_BYTES:  # revision 7
        d.method = r.u8()
        for _ in range(3):
            r.u8()  # reserved
        d.covariance_upper = [r.f32() for _ in range(21)]
        if not all(math.isfinite(c) for c in d.covariance_upper):
            raise DecodeError(DecodeStatus.NON_FINITE, "covariance")
        known = REPLY_DETAIL_ESTIMATE_BYTES
    for _ in range(size - known):
        r.u8()  # a later revision's fields
    if not (math.isfinite(d.window_warp_m) and math.isfinite(d.window_warp_deg)):
        raise DecodeError(DecodeStatus.NON_FINITE, "window warp")
    return d
