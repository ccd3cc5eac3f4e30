"""End to end: build/bin/segmatch-server serves maps/tiny-3 (the regression map of the tiny
simulated city, seed 3) and the Python client localizes a real query against it.

The query is made the cheapest way that still goes through the real tools: segmatch-sim
regenerates the city's revisit drive exactly as scripts/make-regression-map.sh does (same seed
and lengths, ~12 s on 2 cores, ~1.1 GB of scans written to a temporary folder and deleted at
once); 8 scans of its last 40 m before frame 141 (one every 5 m, a frame maps/tiny-3/golden.json
lists as localized) are put in a local frame and cropped to the map's 60 m cylinder: ~1 M points,
16 MB as LOCALIZE. The local frame is the sensor's first pose of that drive (odometry without
drift), so the true T_map_local is known exactly from the simulator's ground truth.
"""

from __future__ import annotations

import math
import os
import shutil
import socket
import struct
import subprocess
import tempfile
import unittest
from pathlib import Path

import numpy as np

import segmatch
from _support import BIN_DIR, BIN_DIR_REQUIRED, SOURCE_DIR, ServerProcess, read_frame
from segmatch import ConnectionLost, ErrorCode, LocalizeStatus, Prior, ServerError
from segmatch import protocol as p

# Stored compressed (maps/tiny-3/map.sqlite.tar.xz); CMake unpacks it into the build tree.
MAP = Path(os.environ.get("SEGMATCH_TINY3_MAP", SOURCE_DIR / "build" / "maps" / "tiny-3" / "map.sqlite"))
QUERY_FRAME = 141  # of sequence 01; localized in maps/tiny-3/golden.json
QUERY_SPAN_M, QUERY_EVERY_M = 40.0, 5.0
TOKEN = "python-client-test-token"


def load_poses(path: Path) -> np.ndarray:
    """KITTI-style rows of 12 values (3x4, row-major) as 4x4 matrices."""
    rows = np.loadtxt(path).reshape(-1, 3, 4)
    T = np.tile(np.eye(4), (len(rows), 1, 1))
    T[:, :3, :] = rows
    return T


def make_query(world: Path, radius_m: float):
    """(points (N, 4) float32 in the local frame, T_local_sensor, true T_map_local)."""
    T_world_lidar = load_poses(world / "ground_truth" / "lidar_poses_01.txt")
    # The map's frame is the first lidar pose of sequence 00 (segmatch-mapbuilder's poses.txt).
    T_world_map = load_poses(world / "ground_truth" / "lidar_poses_00.txt")[0]
    T_local_world = np.linalg.inv(T_world_lidar[0])
    odometer = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(T_world_lidar[:, :3, 3], axis=0), axis=1))])
    frames, last = [], None
    for i in range(QUERY_FRAME, -1, -1):  # newest first, so the query frame itself is kept
        if odometer[QUERY_FRAME] - odometer[i] > QUERY_SPAN_M:
            break
        if last is None or odometer[last] - odometer[i] >= QUERY_EVERY_M:
            frames.append(i)
            last = i
    T_local_sensor = T_local_world @ T_world_lidar[QUERY_FRAME]
    centre = T_local_sensor[:2, 3]
    clouds = []
    for i in frames:
        scan = np.fromfile(world / "sequences" / "01" / "velodyne" / f"{i:06d}.bin", dtype=np.float32).reshape(-1, 4)
        T = T_local_world @ T_world_lidar[i]
        xyz = scan[:, :3] @ T[:3, :3].T + T[:3, 3]
        keep = np.hypot(xyz[:, 0] - centre[0], xyz[:, 1] - centre[1]) <= radius_m
        clouds.append(np.hstack([xyz[keep], scan[keep, 3:]]).astype(np.float32))
    return np.vstack(clouds), T_local_sensor, np.linalg.inv(T_world_map) @ np.linalg.inv(T_local_world)


def pose_error(A: np.ndarray, B: np.ndarray):
    """(metres, degrees) between two 4x4 poses."""
    R = A[:3, :3].T @ B[:3, :3]
    return float(np.linalg.norm(A[:3, 3] - B[:3, 3])), math.degrees(math.acos(np.clip((np.trace(R) - 1) / 2, -1, 1)))


def require_binaries(*names: str) -> None:
    missing = [n for n in names if not (BIN_DIR / n).exists()]
    if missing and BIN_DIR_REQUIRED:
        raise AssertionError(f"SEGMATCH_BIN_DIR={BIN_DIR} lacks {missing}: build them first")
    if missing:
        raise unittest.SkipTest(f"{BIN_DIR} lacks {missing}: set SEGMATCH_BIN_DIR to the C++ build's bin folder")


class EndToEnd(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        require_binaries("segmatch-server", "segmatch-sim")
        cls.tmp = Path(tempfile.mkdtemp(prefix="segmatch_python_e2e_"))
        try:
            world = cls.tmp / "world"
            # As scripts/make-regression-map.sh: the same seed and lengths give the same drive.
            sim = subprocess.run([str(BIN_DIR / "segmatch-sim"), "--preset", "tiny", "--seed", "3", "--length-00-m",
                                  "250", "--length-01-m", "200", "--no-images", "--no-labels", "--out", str(world)],
                                 stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=600)
            if sim.returncode != 0:
                raise AssertionError(f"segmatch-sim exited {sim.returncode}:\n{sim.stdout[-3000:]}")
            cls.server = ServerProcess(MAP, log_path=cls.tmp / "server.log")
            cls.client = segmatch.Client("127.0.0.1", cls.server.port, timeout_s=60)
            radius = cls.client.info().parameters()["local_cloud"]["radius_m"]
            cls.points, cls.T_local_sensor, cls.T_map_local_true = make_query(world, radius)
            shutil.rmtree(world)  # 1.1 GB of scans: gone before the tests run
        except BaseException:
            cls.tearDownClass()
            raise

    @classmethod
    def tearDownClass(cls):
        if getattr(cls, "client", None):
            cls.client.close()
        if getattr(cls, "server", None):
            cls.assert_stopped_cleanly(cls.server)
        shutil.rmtree(cls.tmp, ignore_errors=True)

    @staticmethod
    def assert_stopped_cleanly(server: ServerProcess) -> None:
        code = server.stop()
        if code != 0:
            raise AssertionError(f"segmatch-server exited {code} on SIGTERM:\n{server.log_path.read_text()[-3000:]}")

    def test_info_describes_the_map(self):
        info = self.client.info()
        self.assertEqual(info.map_name, "tiny-3")
        self.assertEqual(info.segment_count, 175)
        self.assertEqual(info.protocol_version, 1)
        self.assertTrue(all(lo < hi for lo, hi in zip(info.extent_min[:2], info.extent_max[:2])))
        self.assertEqual(info.parameters()["voxel"]["leaf_m"], 0.1)

    def test_ping(self):
        self.assertEqual(self.client.ping(0xFEDCBA9876543210), 0xFEDCBA9876543210)

    def test_localizes_close_to_the_truth(self):
        self.assertGreater(len(self.points), 100_000)
        r = self.client.localize(self.points, T_local_sensor=self.T_local_sensor, request_id=QUERY_FRAME)
        self.assertEqual(r.status, LocalizeStatus.LOCALIZED, r.reason)
        self.assertEqual(r.request_id, QUERY_FRAME)
        self.assertEqual(r.reason, "")
        err_m, err_deg = pose_error(r.T_map_local @ self.T_local_sensor, self.T_map_local_true @ self.T_local_sensor)
        print(f"\n[python e2e] {len(self.points)} points: {r.inliers} inliers, support {r.support}, confidence "
              f"{r.confidence:.2f}, error {err_m:.3f} m {err_deg:.3f} deg, server {r.timings.server_total:.0f} ms")
        self.assertLess(err_m, 0.2)
        self.assertLess(err_deg, 1.0)
        self.assertGreaterEqual(r.inliers, 4)
        self.assertEqual(len(r.matched_segment_ids), r.inliers)
        self.assertTrue(0.0 < r.confidence <= 1.0)
        self.assertGreater(r.timings.total, 0.0)
        self.assertGreaterEqual(r.timings.server_total, r.timings.total)
        # The same query given as position + w x y z quaternion gives the same answer.
        q = segmatch.Pose.from_matrix(self.T_local_sensor).q_wxyz
        again = self.client.localize(self.points, sensor_position=self.T_local_sensor[:3, 3], sensor_orientation=q)
        np.testing.assert_allclose(again.T_map_local, r.T_map_local, atol=1e-6)

    def test_a_prior_narrows_the_search(self):
        fair = self.T_map_local_true.copy()
        fair[:3, 3] += [5.0, -3.0, 0.0]
        r = self.client.localize(self.points, T_local_sensor=self.T_local_sensor, prior=Prior(fair, 20.0, 15.0))
        self.assertEqual(r.status, LocalizeStatus.LOCALIZED, r.reason)
        # Radius 0 keeps revision 1's meaning: a global search, then OUTSIDE_PRIOR with the pose.
        far = self.T_map_local_true.copy()
        far[:3, 3] += [150.0, 0.0, 0.0]
        r = self.client.localize(self.points, T_local_sensor=self.T_local_sensor, prior=Prior(far, 0.0))
        self.assertEqual(r.status, LocalizeStatus.OUTSIDE_PRIOR, r.reason)
        self.assertEqual(r.refusal, 0, "not asked for")
        r = self.client.localize(self.points, T_local_sensor=self.T_local_sensor, prior=Prior(far, 0.0),
                                 refusal_code=True)
        self.assertEqual(r.status, LocalizeStatus.OUTSIDE_PRIOR, r.reason)
        self.assertEqual((r.refusal, r.refusal_name), (p.RefusalCode.OUTSIDE_PRIOR, "OUTSIDE_PRIOR"))
        self.assertLess(pose_error(r.T_map_local, self.T_map_local_true)[0], 0.2)

    def test_bad_frames_get_the_error_the_codec_predicts_and_keep_the_connection(self):
        # Raw frames through the codec: the client itself refuses such input before sending.
        good = bytearray(p.encode(p.Localize(1, 0, points=np.zeros((2, 3), dtype=np.float32))))
        bad_quaternion, nan_point = bytearray(good), bytearray(good)
        struct.pack_into("<d", bad_quaternion, p.HEADER_BYTES + 36, 1.5)  # sensor orientation w
        struct.pack_into("<f", nan_point, p.HEADER_BYTES + 140, math.nan)
        unknown = p.MAGIC + struct.pack("<HHI", 1, 0x0042, 4) + b"\0" * 4
        with socket.create_connection(("127.0.0.1", self.server.port), timeout=30) as s:
            for frame, code in ((bad_quaternion, ErrorCode.BAD_QUATERNION), (nan_point, ErrorCode.NON_FINITE),
                                (unknown, ErrorCode.UNKNOWN_TYPE)):
                s.sendall(frame)
                header, payload = read_frame(s)
                reply = p.decode_payload(header.type, payload)
                self.assertIsInstance(reply, p.Error)
                self.assertEqual(reply.code, code, reply.message)
                if frame is not unknown:
                    with self.assertRaises(segmatch.DecodeError) as ctx:
                        p.decode_frame(bytes(frame))
                    self.assertEqual(ctx.exception.status.error_code, code, "the Python codec agrees")
                s.sendall(p.encode(p.Ping(7)))  # the connection stays usable (docs/protocol.md 7)
                header, payload = read_frame(s)
                self.assertEqual(p.decode_payload(header.type, payload), p.Pong(7))

    def test_token_and_frame_limit_errors(self):
        token_file = self.tmp / "token"
        token_file.write_text(TOKEN + "\n")
        with ServerProcess(MAP, "--token-file", str(token_file), "--max-frame-mb", "1",
                           log_path=self.tmp / "server-token.log") as server:
            with self.assertRaises(ServerError) as ctx:
                segmatch.Client("127.0.0.1", server.port, token="wrong")
            self.assertEqual(ctx.exception.code, ErrorCode.AUTH_FAILED)
            with self.assertRaises(ServerError) as ctx:
                segmatch.Client("127.0.0.1", server.port).ping(1)
            self.assertEqual(ctx.exception.code, ErrorCode.AUTH_REQUIRED)
            with segmatch.Client("127.0.0.1", server.port, token=TOKEN) as c:
                self.assertEqual(c.ping(3), 3)
                with self.assertRaises(ServerError) as ctx:  # 1.6 MB > --max-frame-mb 1
                    c.localize(self.points[:100_000])
                self.assertEqual(ctx.exception.code, ErrorCode.FRAME_TOO_LARGE)
                # The server closed that connection: the next request is re-sent once on a new
                # one, after a HELLO with the token.
                self.assertEqual(c.ping(4), 4)
                self.assertEqual(c.retries_used, 1)
            with segmatch.Client("127.0.0.1", server.port, token=TOKEN, retries=0) as c:
                c.localize(self.points[:1000])
                server.proc.terminate()
                server.proc.wait(timeout=30)
                with self.assertRaises((ConnectionLost, segmatch.ConnectError)):
                    c.ping(5)
            self.assertEqual(server.proc.returncode, 0)


if __name__ == "__main__":
    unittest.main()
