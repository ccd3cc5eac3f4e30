"""The Python codec against the frames the C++ codec wrote (tests/data/protocol/, and the older
revisions' tests/api/golden/): each decodes to the values tests/api/protocol_data_test.cpp wrote
(listed in tests/data/protocol/README.md), re-encodes to the same bytes, and the values encoded
here give the same bytes. Malformed frames fail with the C++ codec's DecodeStatus."""

from __future__ import annotations

import dataclasses
import math
import random
import re
import struct
import unittest

import numpy as np

from _support import GOLDEN_V1_V4, PROTOCOL_DATA
from segmatch import protocol as p
from segmatch import DecodeError, DecodeStatus, ErrorCode, Pose, ServerError
from segmatch.segments import SEGMENTS_FLAG_NEWEST_SCANS, segments_digest

PARAMETERS_JSON = '{"voxel":{"leaf_m":0.1,"min_points_per_voxel":2}}'
NONCE = 0x0123456789ABCDEF
YAW90 = (math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4))  # w x y z
TIMINGS = p.Timings(0.5, 1.25, 2.5, 3.75, 0.125, 4.0, 0.25, 5.5, 17.875, 18.5)


def pts(rows):
    return np.array(rows, dtype=np.float32)


def localized_reply(**changes):
    r = p.LocalizeReply(7, p.LocalizeStatus.LOCALIZED, "", Pose((YAW90[0], 0.0, 0.0, -YAW90[3]), (162.5, 84.25, 3.5)),
                        3, 0.875, 12, [4, 17, 1 << 40], TIMINGS)
    for k, v in changes.items():
        setattr(r, k, v)
    return r


# The messages protocol_data_test.cpp writes, built here from the same values (segments aside:
# making quantised segments is the C++ vehicle library's job).
EXPECTED = {
    "hello.bin": p.Hello("segmatch-token-1"),
    "hello_ok.bin": p.HelloOk(),
    "ping.bin": p.Ping(NONCE),
    "pong.bin": p.Pong(NONCE),
    "info.bin": p.Info(),
    "info_reply.bin": p.InfoReply(1, "tiny-3", 175, (-51.625, 90.5, -2.5), (87.625, 165.125, 2.625), PARAMETERS_JSON),
    "localize_global.bin": p.Localize(7, 0, (0.25, -1.5, 1.75), (0.5, 0.5, -0.5, 0.5), points=pts(
        [[1, 2, 3], [-4.5, 0.25, 10], [12.125, -7, 0.5], [0.1, 0.2, 0.3]])),
    "localize_prior_voxelized.bin": p.Localize(
        0x0102030405060708, p.FLAG_HAS_PRIOR | p.FLAG_VOXELIZED | p.FLAG_PRIOR_HEADING, (1.5, -2.25, 1.73),
        (math.cos(math.pi / 12), 0.0, 0.0, math.sin(math.pi / 12)), Pose(YAW90, (100.0, 50.0, -3.0)), 20.0, 15.0,
        pts([[1, 2, 3, 0.5], [-4, 5.25, 0, 1], [7, -8, 9.5, 0]])),
    "localize_reply_localized.bin": localized_reply(),
    "localize_reply_not_localized.bin": p.LocalizeReply(8, p.LocalizeStatus.NOT_LOCALIZED, "too few segments: 2 < 4",
                                                        Pose(), 0, 0.0, 0, [], TIMINGS),
    "localize_reply_outside_prior.bin": localized_reply(request_id=9, status=p.LocalizeStatus.OUTSIDE_PRIOR,
                                                        reason="pose 152.3 m from the prior (radius 0 m)",
                                                        matched_segment_ids=[1, 2, 3]),
    "localize_refusal_code.bin": p.Localize(12, p.FLAG_REFUSAL_CODE, (0.25, -1.5, 1.75), (0.5, 0.5, -0.5, 0.5),
                                            points=pts([[1, 2, 3], [-4.5, 0.25, 10], [12.125, -7, 0.5], [0.1, 0.2, 0.3]])),
    "localize_reply_refused.bin": p.LocalizeReply(
        12, p.LocalizeStatus.NOT_LOCALIZED, "ambiguous: two distinct poses are supported by 16 and 15 query segments",
        Pose(), 0, 0.0, 0, [], TIMINGS, refusal=p.RefusalCode.AMBIGUOUS),
    "localize_detail.bin": p.Localize(13, p.FLAG_DETAIL, (0.25, -1.5, 1.75), (0.5, 0.5, -0.5, 0.5),
                                      points=pts([[1, 2, 3], [-4.5, 0.25, 10], [12.125, -7, 0.5], [0.1, 0.2, 0.3]])),
    "localize_reply_detail.bin": localized_reply(request_id=13, detail=p.ReplyDetail(0.375, 0.25, 1234)),
    "localize_reply_estimate.bin": localized_reply(request_id=14, detail=p.ReplyDetail(
        0.125, 0.0625, 2000, method=1, covariance_upper=[(k + 1) / 4096.0 for k in range(21)])),
    "localize_newest.bin": p.Localize(11, p.FLAG_HAS_PRIOR | p.FLAG_NEWEST_SCANS, (1.0, 2.0, 0.5), (1.0, 0.0, 0.0, 0.0),
                                      Pose((1.0, 0.0, 0.0, 0.0), (100.0, 200.0, 0.0)), 5.0,
                                      points=pts([[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
                                      newest_points=pts([[1.5, -2, 0.25], [3, 4, -0.5]])),
    "localize_reply_off_map.bin": p.LocalizeReply(
        11, p.LocalizeStatus.NOT_LOCALIZED,
        "the vehicle's newest scans do not lie on the map's surfaces at the answer (fitness 0.53, at least 0.55)",
        Pose(), 0, 0.0, 0, [], TIMINGS, refusal=p.RefusalCode.OFF_MAP),
    "localize_track.bin": p.Localize(17, p.FLAG_HAS_PRIOR | p.FLAG_NEWEST_SCANS | p.FLAG_TRACK, (1.0, 2.0, 0.5),
                                     (1.0, 0.0, 0.0, 0.0), Pose((1.0, 0.0, 0.0, 0.0), (100.0, 200.0, 0.0)), 3.0,
                                     points=pts([[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
                                     newest_points=pts([[1.5, -2, 0.25], [3, 4, -0.5]])),
    "localize_reply_tracking_lost.bin": p.LocalizeReply(
        16, p.LocalizeStatus.NOT_LOCALIZED, "tracking on the surface layer: registration fitness 0.61 below 0.75",
        Pose(), 0, 0.0, 0, [], TIMINGS, refusal=p.RefusalCode.TRACKING_LOST),
    "localize_reply_surfaces.bin": localized_reply(request_id=16, detail=p.ReplyDetail(
        0.0, 0.0, 3100, method=2, covariance_upper=[(k + 2) / 8192.0 for k in range(21)])),
    "localize_reply_places.bin": localized_reply(request_id=17, detail=p.ReplyDetail(  # revision 12: a cold start
        0.0, 0.0, 5200, method=3, covariance_upper=[(k + 3) / 8192.0 for k in range(21)])),
    "error.bin": p.Error(ErrorCode.NON_FINITE, "NaN or Inf value"),
}


# Revision 8's frame, written by tests/api/protocol_data_test.cpp (the C++ side): until it is,
# the checks of every frame leave it out and test_newest_scans_frame skips.
NEWEST = "localize_newest.bin"


def stored(name: str, folder=PROTOCOL_DATA) -> bytes:
    return (folder / name).read_bytes()


def expected_stored() -> dict:
    """EXPECTED without NEWEST while its file is missing."""
    return {n: m for n, m in EXPECTED.items() if n != NEWEST or (PROTOCOL_DATA / n).exists()}


class StoredFrames(unittest.TestCase):
    def test_every_stored_frame_is_checked(self):
        names = {f.name for f in PROTOCOL_DATA.glob("*.bin")}
        self.assertEqual(names, set(expected_stored()) | {"localize_segments.bin", "localize_segments_newest.bin",
                                                          "localize_segments_track.bin"})

    def test_every_frame_decodes_and_reencodes_byte_for_byte(self):
        files = sorted(PROTOCOL_DATA.glob("*.bin")) + sorted(GOLDEN_V1_V4.glob("*.bin"))
        self.assertGreaterEqual(len(files), 17)
        for f in files:
            with self.subTest(frame=f.name):
                data = f.read_bytes()
                self.assertEqual(p.encode(p.decode_frame(data)), data)

    def test_values_encoded_here_give_the_cpp_bytes(self):
        for name, message in expected_stored().items():
            with self.subTest(frame=name):
                self.assertEqual(p.encode(message).hex(), stored(name).hex())

    def test_decoded_values(self):
        for name, want in expected_stored().items():
            with self.subTest(frame=name):
                got = p.decode_frame(stored(name))
                self.assertIs(type(got), type(want))
                for key, value in vars(want).items():
                    if isinstance(value, np.ndarray):
                        np.testing.assert_array_equal(getattr(got, key), value)
                        self.assertEqual(getattr(got, key).dtype, np.float32)
                    else:
                        self.assertEqual(getattr(got, key), value, key)

    def test_newest_scans_frame(self):
        """Revision 8: EXPECTED's localize_newest.bin, as protocol_data_test.cpp wrote it."""
        if not (PROTOCOL_DATA / NEWEST).exists():
            self.skipTest(f"{NEWEST} is not written yet (tests/api/protocol_data_test.cpp, revision 8)")
        data = stored(NEWEST)
        self.assertEqual(len(data), p.HEADER_BYTES + 140 + 3 * 12 + 4 + 2 * 12, "stride 3, no heading tolerance")
        m = p.decode_frame(data)
        self.assertEqual((m.request_id, m.flags, m.prior_radius_m), (11, p.FLAG_HAS_PRIOR | p.FLAG_NEWEST_SCANS, 5.0))
        self.assertEqual((m.sensor_position, m.sensor_orientation_wxyz), ((1.0, 2.0, 0.5), (1.0, 0.0, 0.0, 0.0)))
        self.assertEqual((m.prior.q_wxyz, m.prior.t), ((1.0, 0.0, 0.0, 0.0), (100.0, 200.0, 0.0)))
        np.testing.assert_array_equal(m.points, np.eye(3))
        np.testing.assert_array_equal(m.newest_points, [[1.5, -2, 0.25], [3, 4, -0.5]])
        self.assertEqual(m.newest_points.dtype, np.float32)
        self.assertEqual(p.encode(m), data, "re-encoded byte for byte")
        self.assertEqual(p.encode(EXPECTED[NEWEST]), data)

    def test_poses_are_w_x_y_z_and_matrices_map_local_into_map(self):
        r = p.decode_frame(stored("localize_prior_voxelized.bin"))
        self.assertAlmostEqual(r.prior.q_wxyz[0], math.sqrt(0.5), places=15)  # w first: yaw +90 deg
        T = r.prior.matrix()
        np.testing.assert_allclose(T @ [1, 0, 0, 1], [100, 51, -3, 1], atol=1e-12)  # x_local -> y_map
        reply = p.decode_frame(stored("localize_reply_localized.bin"))
        np.testing.assert_allclose(reply.T_map_local[:3, 3], [162.5, 84.25, 3.5])
        np.testing.assert_allclose(reply.T_map_local[:2, :2], [[0, 1], [-1, 0]], atol=1e-15)  # yaw -90 deg

    def test_localize_segments(self):
        m = p.decode_frame(stored("localize_segments.bin"))
        self.assertEqual(m.parameters_digest, segments_digest(PARAMETERS_JSON), "FNV-1a as the C++ digest")
        self.assertEqual((m.request_id, m.flags, m.prior_radius_m, m.prior_heading_tolerance_deg), (11, 3, 12.5, 7.5))
        self.assertEqual(len(m.segments), 2)
        for k, s in enumerate(m.segments):
            c = 4.0 * (k + 1)
            np.testing.assert_allclose(s.points, [[c, 1, 0.5], [c + 0.75, 1.5, 0.25], [c - 0.5, 0.25, 2]], atol=1e-3)
            np.testing.assert_allclose(s.eigen, [0.125 * (i + k + 1) for i in range(7)])
            self.assertEqual([i for i in range(640) if s.esf[i] != 0], [i for i in range(640) if i % 64 == k])
            self.assertEqual(s.esf[k], 0.0625)
        v3 = p.decode_frame(stored("localize_segments_v3.bin", GOLDEN_V1_V4))
        self.assertEqual(v3.request_id, 42)

    def test_localize_segments_with_newest_scans(self):
        """Revision 10: LOCALIZE_SEGMENTS bit 4, the newest scans after the segments."""
        m = p.decode_frame(stored("localize_segments_newest.bin"))
        self.assertEqual((m.request_id, m.flags, len(m.segments)), (15, 21, 1))
        self.assertTrue(m.flags & SEGMENTS_FLAG_NEWEST_SCANS)
        np.testing.assert_array_equal(m.newest_points, [[1.5, -2, 0.25], [3, 4, -0.5], [0.125, 0, 8]])
        self.assertEqual(m.newest_points.dtype, np.float32)
        self.assertEqual(p.encode(m), stored("localize_segments_newest.bin"))
        data = bytearray(stored("localize_segments_newest.bin"))
        struct.pack_into("<I", data, len(data) - 4 - 36, 4)  # one newest point more than sent
        with self.assertRaises(DecodeError) as e:
            p.decode_frame(bytes(data))
        self.assertEqual(e.exception.status, DecodeStatus.BAD_POINT_COUNT)


class ProtocolDocument(unittest.TestCase):
    def test_the_annotated_localize_in_docs_matches_its_file(self):
        """docs/protocol.md 10.1 shows localize_global.bin byte by byte: the table must stay true."""
        doc = (PROTOCOL_DATA.parents[2] / "docs" / "protocol.md").read_text()
        section = doc.split("### 10.1 LOCALIZE, byte by byte", 1)[1]
        shown = bytearray()
        for m in re.finditer(r"^\| (\d+)[^|]*\| (?:(\d+) × )?`([0-9A-F ]+)` \|", section, re.M):
            self.assertEqual(int(m.group(1)), len(shown), "offsets follow each other")
            shown += bytes.fromhex(m.group(3)) * int(m.group(2) or 1)
        self.assertEqual(bytes(shown), stored("localize_global.bin"))


def localize_frame(**changes) -> bytearray:
    m = p.Localize(5, p.FLAG_HAS_PRIOR, (1.0, 2.0, 3.0), points=pts([[1, 2, 3, 4], [5, 6, 7, 8]]), prior_radius_m=10.0)
    for k, v in changes.items():
        setattr(m, k, v)
    return bytearray(p.encode(m))


def status_of(frame, **kwargs):
    """The DecodeStatus a frame fails with, None if it decodes (anything else propagates)."""
    try:
        p.decode_frame(bytes(frame), **kwargs)
    except DecodeError as e:
        return e.status
    return None


H = p.HEADER_BYTES  # payload offsets below are docs/protocol.md 5.4's


class MalformedFrames(unittest.TestCase):
    def test_header(self):
        good = p.encode(p.Ping(1))
        self.assertEqual(status_of(b"SGMX" + good[4:]), DecodeStatus.BAD_MAGIC)
        self.assertEqual(status_of(good[:4] + b"\x02\x00" + good[6:]), DecodeStatus.BAD_VERSION)
        self.assertEqual(status_of(good[:6] + b"\x42\x00" + good[8:]), DecodeStatus.UNKNOWN_TYPE)
        self.assertEqual(status_of(good[:11]), DecodeStatus.INCOMPLETE)
        self.assertEqual(status_of(good, max_payload_bytes=7), DecodeStatus.TOO_LARGE)
        with self.assertRaises(DecodeError) as ctx:
            p.decode_header(good[:6] + b"\x42\x00" + good[8:])
        self.assertEqual(ctx.exception.header.payload_bytes, 8, "an unknown type's payload can be skipped")

    def test_every_truncation_and_extra_byte_is_refused(self):
        for f in sorted(PROTOCOL_DATA.glob("*.bin")):
            data = f.read_bytes()
            for n in range(len(data)):
                self.assertIsNotNone(status_of(data[:n]), f"{f.name} cut to {n}")
            self.assertEqual(status_of(data + b"\0"), DecodeStatus.TRAILING_BYTES, f.name)
            longer = bytearray(data + b"\0")  # the extra byte inside the payload
            struct.pack_into("<I", longer, 8, len(data) + 1 - H)
            self.assertIsNotNone(status_of(longer), f.name)

    def test_localize_fields(self):
        cases = {
            DecodeStatus.BAD_POINT_COUNT: [(H + 132, "<I", 3)],
            DecodeStatus.BAD_STRIDE: [(H + 136, "<I", 5)],
            DecodeStatus.NON_FINITE: [(H + 140 + 4, "<f", math.nan)],
            DecodeStatus.BAD_FIELD: [(H + 124, "<d", -1.0)],
        }
        for status, patches in cases.items():
            f = localize_frame()
            for offset, fmt, value in patches:
                struct.pack_into(fmt, f, offset, value)
            self.assertEqual(status_of(f), status)
        f = localize_frame()
        struct.pack_into("<d", f, H + 124, math.inf)
        self.assertEqual(status_of(f), DecodeStatus.NON_FINITE, "radius")
        f = localize_frame()
        struct.pack_into("<I", f, H + 8, 1 << 6)  # the first bit revision 8 does not define
        self.assertEqual(status_of(f), DecodeStatus.BAD_FIELD, "unknown flag bit")
        f = localize_frame(prior_heading_tolerance_deg=-1.0, flags=p.FLAG_PRIOR_HEADING)
        self.assertEqual(status_of(f), DecodeStatus.BAD_FIELD, "negative heading tolerance")

    def test_quaternions_off_by_more_than_1e3_are_refused(self):
        for offset in (H + 36, H + 68):  # sensor orientation, prior
            f = localize_frame()
            struct.pack_into("<d", f, offset, 1.01)
            self.assertEqual(status_of(f), DecodeStatus.BAD_QUATERNION)
            struct.pack_into("<d", f, offset, 1.0005)
            self.assertIsNone(status_of(f), "within 1e-3 of unit: accepted")
            struct.pack_into("<d", f, offset, math.nan)
            self.assertEqual(status_of(f), DecodeStatus.NON_FINITE)

    def test_reply_fields(self):
        base = bytearray(stored("localize_reply_localized.bin"))
        for offset, fmt, value, status in ((H + 8, "<H", 3, DecodeStatus.BAD_FIELD),  # unknown status
                                           (H + 76, "<f", math.nan, DecodeStatus.NON_FINITE)):  # confidence: after id, status, reason "", pose, inliers
            f = bytearray(base)
            struct.pack_into(fmt, f, offset, value)
            self.assertEqual(status_of(f), status)
        # Revision 5: the former reserved field is the refusal code; every value decodes, a
        # later revision's code included.
        for code, name in ((6, "AMBIGUOUS"), (4, "OUTSIDE_PRIOR"), (999, "UNKNOWN")):
            f = bytearray(base)
            struct.pack_into("<H", f, H + 10, code)
            reply = p.decode_frame(bytes(f))
            self.assertEqual((reply.refusal, reply.refusal_name), (code, name))
            self.assertEqual(p.encode(reply), bytes(f), "re-encoded byte for byte")
        info = bytearray(stored("info_reply.bin"))
        struct.pack_into("<H", info, H + 2, 1)
        self.assertEqual(status_of(info), DecodeStatus.BAD_FIELD, "INFO_REPLY reserved")

    def test_strings_over_the_limit_and_other_types(self):
        self.assertEqual(status_of(p.encode(p.Hello("12345")), max_string_bytes=4), DecodeStatus.BAD_FIELD)
        self.assertIsNone(status_of(p.encode(p.Hello("1234")), max_string_bytes=4))
        with self.assertRaises(DecodeError) as ctx:
            p.decode_frame(p.encode(p.Pong(1)), expected=p.Ping)
        self.assertEqual(ctx.exception.status, DecodeStatus.UNKNOWN_TYPE)

    def test_random_mutations_only_ever_raise_decode_error(self):
        rng = random.Random(19)
        frames = [f.read_bytes() for f in sorted(PROTOCOL_DATA.glob("*.bin"))]
        for _ in range(3000):
            f = bytearray(rng.choice(frames))
            for _ in range(rng.randint(1, 4)):
                f[rng.randrange(len(f))] = rng.randrange(256)
            status_of(f)  # anything but DecodeError propagates and fails the test


class ErrorMapping(unittest.TestCase):
    def test_decode_status_maps_to_the_servers_error_code(self):  # C++ error_code_for
        self.assertEqual(DecodeStatus.BAD_STRIDE.error_code, ErrorCode.BAD_POINT_COUNT)
        self.assertEqual(DecodeStatus.BAD_QUATERNION.error_code, ErrorCode.BAD_QUATERNION)
        self.assertEqual(DecodeStatus.TOO_LARGE.error_code, ErrorCode.FRAME_TOO_LARGE)
        for s in (DecodeStatus.TRUNCATED, DecodeStatus.TRAILING_BYTES, DecodeStatus.BAD_FIELD):
            self.assertEqual(s.error_code, ErrorCode.MALFORMED)

    def test_error_codes_match_the_protocol_table(self):
        self.assertEqual([(c.name, int(c)) for c in ErrorCode][-3:],
                         [("SHUTTING_DOWN", 14), ("PARAMETERS_MISMATCH", 15), ("REQUEST_TIMEOUT", 16)])
        self.assertEqual(p.decode_frame(stored("error_request_timeout_v4.bin", GOLDEN_V1_V4)).code,
                         ErrorCode.REQUEST_TIMEOUT)

    def test_an_unknown_error_code_is_kept_as_its_number(self):  # docs/protocol.md 8, rule 6
        e = p.decode_frame(p.encode(p.Error(999, "from the future")))
        self.assertEqual(e.code, 999)
        err = ServerError(e.code, e.message)
        self.assertEqual(err.code, 999)
        self.assertIn("999", str(err))
        self.assertIs(ServerError(7, "x").code, ErrorCode.NON_FINITE)


class Poses(unittest.TestCase):
    def test_matrix_round_trip_and_bad_matrices(self):
        T = Pose((0.5, 0.5, -0.5, 0.5), (1.0, 2.0, 3.0)).matrix()
        back = Pose.from_matrix(T)
        np.testing.assert_allclose(back.matrix(), T, atol=1e-15)
        for bad in (np.eye(3), np.diag([1.0, 1.0, -1.0, 1.0]), np.full((4, 4), np.nan), 2 * np.eye(4)):
            with self.assertRaises(ValueError):
                Pose.from_matrix(bad)

    def test_ros_order_converts(self):
        from segmatch import ros_xyzw_from_wxyz, wxyz_from_ros_xyzw
        self.assertEqual(wxyz_from_ros_xyzw((0.0, 0.0, 0.6, 0.8)), (0.8, 0.0, 0.0, 0.6))
        self.assertEqual(ros_xyzw_from_wxyz((0.8, 0.0, 0.0, 0.6)), (0.0, 0.0, 0.6, 0.8))


class NewestScans(unittest.TestCase):
    """Revision 8: the newest scans travel last, behind FLAG_NEWEST_SCANS (after the heading
    tolerance when bit 2 is set too): u32 M, then M x y z f32. Their count must match the payload
    (BAD_POINT_COUNT), their coordinates be finite (NON_FINITE)."""

    NEWEST = [[1.5, -2, 0.25], [3, 4, -0.5]]

    def message(self, flags=p.FLAG_NEWEST_SCANS | p.FLAG_PRIOR_HEADING, newest=NEWEST, points=((1, 2, 3), (4, 5, 6))):
        return p.Localize(3, flags, (0.0, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0), Pose(), 0.0, 4.5, pts(points),
                          newest_points=pts(newest) if len(newest) else np.zeros((0, 3), np.float32))

    def payload(self, **changes) -> bytes:
        return p.encode(self.message(**changes))[H:]

    @staticmethod
    def frame(payload: bytes) -> bytes:
        return p.MAGIC + struct.pack("<HHI", p.VERSION, int(p.MessageType.LOCALIZE), len(payload)) + payload

    def test_the_flag(self):
        self.assertEqual((p.REVISION, p.FLAG_NEWEST_SCANS, p.FLAG_TRACK), (11, 1 << 5, 1 << 6))

    def test_round_trip_with_and_without_the_heading_tolerance(self):
        for flags, points in ((p.FLAG_NEWEST_SCANS | p.FLAG_PRIOR_HEADING, [[1, 2, 3], [4, 5, 6]]),
                              (p.FLAG_NEWEST_SCANS | p.FLAG_HAS_PRIOR, [[1, 2, 3, 0.5], [4, 5, 6, 1]])):
            with self.subTest(flags=flags):
                m = self.message(flags, points=points)
                data = p.encode(m)
                heading = 8 if flags & p.FLAG_PRIOR_HEADING else 0
                self.assertEqual(len(data), H + 140 + 2 * 4 * len(points[0]) + heading + 4 + 2 * 12)
                self.assertEqual(data[-28:], struct.pack("<I6f", 2, *np.ravel(self.NEWEST)), "last: M, then x y z")
                back = p.decode_frame(data)
                self.assertEqual((back.flags, back.prior_heading_tolerance_deg), (flags, 4.5 if heading else 10.0))
                np.testing.assert_array_equal(back.points, points)
                np.testing.assert_array_equal(back.newest_points, self.NEWEST)
                self.assertEqual(back.newest_points.dtype, np.float32)
                self.assertEqual(p.encode(back), data)
        none = p.decode_frame(p.encode(self.message(newest=[])))  # the bit with M = 0: 4 bytes
        self.assertEqual(none.newest_points.shape, (0, 3))

    def test_without_the_bit_the_bytes_are_those_before(self):
        m = dataclasses.replace(EXPECTED["localize_global.bin"], newest_points=pts(self.NEWEST))  # bit 5 clear
        self.assertEqual(p.encode(m), stored("localize_global.bin"))
        self.assertEqual(p.decode_frame(stored("localize_global.bin")).newest_points.shape, (0, 3))
        with self.assertRaisesRegex(ValueError, "newest_points"):
            p.encode(self.message(newest=[[1, 2, 3, 4]]))

    def test_a_count_that_does_not_match_the_payload_is_bad_point_count(self):
        good = self.payload()
        plain = self.payload(flags=p.FLAG_PRIOR_HEADING)  # the same, without bit 5 and its bytes
        with_bit_only = bytearray(plain)
        struct.pack_into("<I", with_bit_only, 8, p.FLAG_PRIOR_HEADING | p.FLAG_NEWEST_SCANS)
        count_3 = bytearray(good)
        struct.pack_into("<I", count_3, len(good) - 28, 3)
        count_max = bytearray(good)
        struct.pack_into("<I", count_max, len(good) - 28, 0xFFFFFFFF)
        cases = {"one point short": good[:-12], "one byte short": good[:-1], "one point over": good + good[-12:],
                 "4 bytes over": good + b"\0" * 4, "no count": bytes(with_bit_only), "count 3": bytes(count_3),
                 "count 2^32-1": bytes(count_max), "newest scans without the bit": plain + good[len(plain):]}
        for what, payload in cases.items():
            self.assertEqual(status_of(self.frame(payload)), DecodeStatus.BAD_POINT_COUNT, what)
        self.assertIsNone(status_of(self.frame(good)))

    def test_a_non_finite_newest_coordinate_is_non_finite(self):
        good = self.payload()
        for offset in (len(good) - 24, len(good) - 4):  # the first and the last coordinate
            for value in (math.nan, math.inf, -math.inf):
                f = bytearray(good)
                struct.pack_into("<f", f, offset, value)
                self.assertEqual(status_of(self.frame(f)), DecodeStatus.NON_FINITE, (offset, value))


if __name__ == "__main__":
    unittest.main()
