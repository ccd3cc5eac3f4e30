"""Blocking TCP client of segmatch-server, behaving as the C++ api::Client (api/src/client.cpp).

Retry policy (the C++ ClientOptions::retries): every request is idempotent, so a request whose
connection is lost before its reply (the server closed or reset it: a replica restarted, a load
balancer moved it) is sent again, `retries` times, on a new connection. That new connection
counts only once a server answered HELLO on it; a connection refused or closed before HELLO_OK
(a dying replica's backlog still accepts) is made again after a pause, 50 ms doubling to 1 s,
for up to reconnect_window_s. Not retried: a timeout (the server may still be working on the
request), an ERROR reply, a failed first connect.
"""

from __future__ import annotations

import itertools
import math
import socket
import time
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from . import protocol as p
from .errors import ClientTimeout, ConnectError, ConnectionLost, DecodeError, ProtocolError, SegmatchError, ServerError
from .pose import Pose, check_quaternion, check_rotation, quaternion_from_rotation

U64_MAX = (1 << 64) - 1


@dataclass(frozen=True)
class Prior:
    """A guess of T_map_local (4x4) and how far, in metres, the sensor's map position may be
    from where the guess puts it. radius_m 0 keeps revision 1's meaning: a global search, then
    OUTSIDE_PRIOR for any other pose. heading_tolerance_deg: None lets the server use 10 deg."""

    T_map_local: np.ndarray
    radius_m: float
    heading_tolerance_deg: Optional[float] = None


class Client:
    """One connection at a time to segmatch-server, used from one thread at a time.

    >>> with Client("127.0.0.1", 7878) as c:
    ...     reply = c.localize(cloud_xyz, T_local_sensor=T)
    """

    def __init__(self, host: str, port: int, token: Optional[str] = None, timeout_s: float = 30.0, retries: int = 1,
                 connect_timeout_s: float = 5.0, reconnect_window_s: float = 5.0,
                 max_payload_bytes: int = p.MAX_PAYLOAD_BYTES):
        """Connects and, with a token, authenticates (HELLO -> HELLO_OK). timeout_s bounds each
        send and each whole reply (a localization takes 0.01-1 s; queues add to it)."""
        if not isinstance(retries, int) or retries < 0:
            raise ValueError(f"retries must be an int >= 0, got {retries!r}")
        for name, v in (("timeout_s", timeout_s), ("connect_timeout_s", connect_timeout_s)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number of seconds, got {v!r}")
        if not (isinstance(reconnect_window_s, (int, float)) and reconnect_window_s >= 0):
            raise ValueError(f"reconnect_window_s must be >= 0, got {reconnect_window_s!r}")
        self.host, self.port, self.token = host, int(port), token or ""
        self.timeout_s, self.retries = float(timeout_s), retries
        self.connect_timeout_s, self.reconnect_window_s = float(connect_timeout_s), float(reconnect_window_s)
        self.max_payload_bytes = max_payload_bytes
        self.retries_used = 0  # requests sent again on a new connection so far
        self._where = f"{host}:{port}"
        self._sock: Optional[socket.socket] = None
        self._broken = True
        self._ids = itertools.count(1)
        try:
            self._open()
        except OSError as e:
            raise ConnectError(f"{self._where}: {e}") from None
        if self.token:
            self._hello()

    # ---- public API -------------------------------------------------------------------------

    def ping(self, nonce: int = 0) -> int:
        """Round trip of one PING; returns the PONG's nonce (checked equal to the one sent)."""
        _check_u64(nonce, "nonce")

        def round_trip():
            self._send(p.encode(p.Ping(nonce)))
            pong = self._expect(p.Pong)
            if pong.nonce != nonce:
                self._fail(ProtocolError, f"PONG nonce {pong.nonce} differs from the PING's {nonce}")
            return pong.nonce
        return self._with_retries(round_trip)

    def info(self) -> p.InfoReply:
        """The served map: name, segment count, extent, parameters JSON (.parameters())."""
        def round_trip():
            self._send(p.encode(p.Info()))
            return self._expect(p.InfoReply)
        return self._with_retries(round_trip)

    def localize(self, points, sensor_position: Sequence[float] = (0.0, 0.0, 0.0),
                 sensor_orientation=(1.0, 0.0, 0.0, 0.0), prior: Optional[Prior] = None, voxelized: bool = False,
                 request_id: Optional[int] = None, T_local_sensor=None, refusal_code: bool = False,
                 newest_points=None) -> p.LocalizeReply:
        """Localizes a local cloud; returns the LOCALIZE_REPLY (.status, .reason, .T_map_local
        4x4, .inliers, .confidence, .support, .matched_segment_ids, .timings).

        points: (N, 3) x y z or (N, 4) x y z intensity in the vehicle's local (odometry) frame;
            sent as float32. voxelized=True says they are already the map's voxel centroids.
        sensor_position, sensor_orientation: the sensor in the local frame; the orientation is a
            quaternion **w x y z** (ROS's geometry_msgs order is x y z w: reorder it with
            segmatch.wxyz_from_ros_xyzw) or a 3x3 rotation matrix. Or give T_local_sensor (4x4).
        prior: a Prior (T_map_local guess, radius, heading tolerance) or None for a global search.
        request_id: u64 echoed in the reply; by default 1, 2, 3, ... per client.
        refusal_code: ask for the reply's RefusalCode (.refusal, .refusal_name; revision 5). A
            server of revision 4 or older answers ServerError MALFORMED to it.
        newest_points: (M, 3) or (M, 4) points of the vehicle's newest scans (the last few metres,
            local frame; intensity dropped), sent behind FLAG_NEWEST_SCANS (revision 8): the server
            refines its answer to them, the sensor's pose now rather than the odometry-warped
            cloud's. None or empty: not sent. A server of revision 7 or older answers ServerError
            MALFORMED to it (resend without them).
        """
        m = p.Localize(request_id=next(self._ids) if request_id is None else _check_u64(request_id, "request_id"))
        if T_local_sensor is not None:
            pose = Pose.from_matrix(T_local_sensor, "T_local_sensor")
            m.sensor_position, m.sensor_orientation_wxyz = pose.t, pose.q_wxyz
        else:
            m.sensor_position = _vector3(sensor_position, "sensor_position")
            m.sensor_orientation_wxyz = _orientation(sensor_orientation)
        m.points = _points(points)
        if voxelized:
            m.flags |= p.FLAG_VOXELIZED
        if refusal_code:
            m.flags |= p.FLAG_REFUSAL_CODE
        if newest_points is not None:
            newest = _points(newest_points, "newest_points")
            if newest.shape[0] > 0:  # empty: nothing to send, the flag stays clear
                m.flags |= p.FLAG_NEWEST_SCANS
                m.newest_points = newest[:, :3]
        if prior is not None:
            if not isinstance(prior, Prior):
                raise TypeError(f"prior must be a segmatch.Prior, got {type(prior).__name__}")
            m.flags |= p.FLAG_HAS_PRIOR
            m.prior = Pose.from_matrix(prior.T_map_local, "prior.T_map_local")
            m.prior_radius_m = _non_negative(prior.radius_m, "prior.radius_m")
            if prior.heading_tolerance_deg is not None:
                m.flags |= p.FLAG_PRIOR_HEADING
                m.prior_heading_tolerance_deg = _non_negative(prior.heading_tolerance_deg, "prior.heading_tolerance_deg")
        return self._localize(p.encode(m), m.request_id)

    def localize_segments(self, message: p.LocalizeSegments) -> p.LocalizeReply:
        """Revision 3: a LOCALIZE_SEGMENTS made elsewhere (wire level, segmatch.segments). A server
        of an earlier revision answers ServerError UNKNOWN_TYPE."""
        return self._localize(p.encode(message), message.request_id)

    @property
    def broken(self) -> bool:
        """After a timeout, a lost connection or an undecodable reply the byte stream is lost: the
        next call connects again (retries > 0) or raises ConnectionLost (retries = 0). A server
        ERROR leaves the connection usable."""
        return self._broken

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        self._broken = True

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ---- retry policy -------------------------------------------------------------------------

    def _with_retries(self, round_trip):
        attempt = 0
        while True:
            try:
                if self._broken and attempt == 0 and self.retries > 0:  # broken by an earlier call
                    self.retries_used += 1
                    self._reconnect()
                return round_trip()
            except ConnectionLost:
                if attempt >= self.retries:
                    raise
                attempt += 1
                self.retries_used += 1
                self._reconnect()

    def _reconnect(self) -> None:
        """Connects until a server answers HELLO (with the token, or empty: a server without a
        token answers any HELLO), pausing 50 ms doubling to 1 s, for reconnect_window_s."""
        give_up = time.monotonic() + self.reconnect_window_s
        pause = 0.05
        while True:
            try:
                self._open()
                self._hello()
                return
            except ConnectionLost:
                # Closed before HELLO_OK: a replica going away. Anything else (an ERROR such as a
                # wrong token, a stalled or garbled handshake) is a live server saying no.
                if time.monotonic() + pause > give_up:
                    raise
            except SegmatchError:
                raise  # before OSError: ClientTimeout is a TimeoutError, hence an OSError
            except OSError as e:  # connect refused, unreachable, timed out
                if time.monotonic() + pause > give_up:
                    raise ConnectError(f"{self._where}: {e}") from None
            time.sleep(pause)
            pause = min(pause * 2, 1.0)

    # ---- frames ---------------------------------------------------------------------------------

    def _open(self) -> None:
        self.close()
        self._sock = socket.create_connection((self.host, self.port), timeout=self.connect_timeout_s)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._broken = False

    def _hello(self) -> None:
        self._send(p.encode(p.Hello(self.token)))
        self._expect(p.HelloOk)

    def _localize(self, frame: bytes, request_id: int) -> p.LocalizeReply:
        def round_trip():
            self._send(frame)
            reply = self._expect(p.LocalizeReply)
            if reply.request_id != request_id:
                self._fail(ProtocolError, f"reply for request {reply.request_id}, expected {request_id}")
            return reply
        return self._with_retries(round_trip)

    def _fail(self, kind, message: str):
        self.close()
        raise kind(f"{self._where}: {message}")

    def _send(self, data: bytes) -> None:
        if self._broken:
            raise ConnectionLost(f"{self._where}: connection is closed")
        try:
            self._sock.settimeout(self.timeout_s)
            self._sock.sendall(data)
        except socket.timeout:
            self._fail(ClientTimeout, f"send timed out after {self.timeout_s} s")
        except OSError as e:
            # A server that refuses a request before reading all of it (too large, bad header)
            # replies ERROR and closes: that ERROR, when it made it here, says more.
            self._raise_pending_error()
            self._fail(ConnectionLost, f"send failed: {e}")

    def _raise_pending_error(self) -> None:
        try:
            header, payload = self._read_frame_raw(time.monotonic() + 0.5)
            error = p.decode_payload(header.type, payload) if header.type == p.MessageType.ERROR else None
        except (OSError, SegmatchError):
            return  # nothing readable: the caller reports the failed send
        if error is not None:
            self.close()
            raise ServerError(error.code, error.message, self._where)

    def _read_exact(self, n: int, deadline: float) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            left = deadline - time.monotonic()
            if left <= 0:
                raise socket.timeout()
            self._sock.settimeout(left)
            chunk = self._sock.recv(min(n - len(buf), 1 << 20))
            if not chunk:
                raise ConnectionResetError("the server closed the connection")
            buf += chunk
        return bytes(buf)

    def _read_frame_raw(self, deadline: float):
        """One whole frame by the deadline; raises socket.timeout, OSError or DecodeError."""
        header = p.decode_header(self._read_exact(p.HEADER_BYTES, deadline), self.max_payload_bytes)
        return header, self._read_exact(header.payload_bytes, deadline)

    def _expect(self, cls):
        if self._broken:
            raise ConnectionLost(f"{self._where}: connection is closed")
        try:
            header, payload = self._read_frame_raw(time.monotonic() + self.timeout_s)
        except socket.timeout:
            self._fail(ClientTimeout, f"no reply within {self.timeout_s} s")
        except DecodeError as e:
            self._fail(ProtocolError, f"bad reply header: {e}")
        except OSError as e:
            self._fail(ConnectionLost, f"reading the reply: {e}")
        try:
            reply = p.decode_payload(header.type, payload)
        except DecodeError as e:
            self._fail(ProtocolError, f"bad {p.MessageType(header.type).name}: {e}")
        if isinstance(reply, p.Error):
            raise ServerError(reply.code, reply.message, self._where)  # the connection stays usable
        if not isinstance(reply, cls):
            self._fail(ProtocolError, f"expected {cls.TYPE.name}, got {p.MessageType(header.type).name}")
        return reply


# ---- argument checks: bad input fails here, with its name, not as a server ERROR -----------------

def _check_u64(v, name: str) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 <= int(v) <= U64_MAX:
        raise ValueError(f"{name} must be an integer in [0, 2^64), got {v!r}")
    return int(v)


def _vector3(v, name: str):
    a = np.asarray(v, dtype=float).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers x y z, got {v!r}")
    return tuple(float(x) for x in a)


def _orientation(q):
    a = np.asarray(q, dtype=float)
    if a.shape == (3, 3):
        return quaternion_from_rotation(check_rotation(a, "sensor_orientation"))
    return check_quaternion(a, "sensor_orientation (w x y z)")


def _non_negative(v, name: str) -> float:
    if not (isinstance(v, (int, float, np.floating, np.integer)) and math.isfinite(v) and v >= 0):
        raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
    return float(v)


def _points(points, name: str = "points") -> np.ndarray:
    a = np.asarray(points)
    if a.ndim != 2 or a.shape[1] not in (3, 4):
        raise ValueError(f"{name} must be an (N, 3) x y z or (N, 4) x y z intensity array, got shape {a.shape}")
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise ValueError(f"{name} must be numbers, got dtype {a.dtype}")
    if a.shape[0] > 0xFFFFFFFF:
        raise ValueError(f"{a.shape[0]} {name} do not fit one frame")
    with np.errstate(over="ignore"):
        f = np.ascontiguousarray(a, dtype="<f4")
    bad = ~np.all(np.isfinite(f), axis=1)
    if bad.any():
        raise ValueError(f"{name} must be finite in float32: {int(bad.sum())} are not, the first at row "
                         f"{int(np.argmax(bad))}: {a[int(np.argmax(bad))]}")
    return f
