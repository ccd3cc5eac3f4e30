"""segmatch.Client against a scripted loopback server: the retry policy of the C++ client
(tests/api/client_retry_test.cpp: a request whose connection is lost is re-sent once on a new
connection that answered HELLO; timeouts and ERROR replies are not retried) and the checks of
bad arguments, which fail before anything is sent."""

from __future__ import annotations

import time
import unittest

import numpy as np

import segmatch
from _support import ScriptedServer
from segmatch import (ClientTimeout, ConnectError, ConnectionLost, ErrorCode, LocalizeStatus, Prior, ProtocolError,
                      ServerError)
from segmatch import protocol as p

CLOUD = np.zeros((10, 3), dtype=np.float32)


class RetryPolicy(unittest.TestCase):
    def test_a_request_lost_with_its_connection_is_sent_once_more_after_a_hello(self):
        with ScriptedServer(drops=1) as s:
            c = segmatch.Client("127.0.0.1", s.port)
            r = c.localize(CLOUD, request_id=31)
            self.assertEqual(r.request_id, 31)
            self.assertEqual(r.status, LocalizeStatus.NOT_LOCALIZED)
            self.assertEqual(r.reason, "scripted")
            self.assertEqual(c.retries_used, 1)
            self.assertEqual(s.connections, 2)
            self.assertEqual(s.requests("LOCALIZE"), 2)
            self.assertEqual(s.log[1:], [(2, "HELLO"), (2, "LOCALIZE")], "HELLO first on the new connection")

    def test_a_second_loss_is_reported(self):
        with ScriptedServer(drops=2) as s:
            c = segmatch.Client("127.0.0.1", s.port)
            with self.assertRaises(ConnectionLost):
                c.ping(5)
            self.assertEqual(s.requests("PING"), 2)
            self.assertTrue(c.broken)

    def test_no_retry_with_retries_0(self):
        with ScriptedServer(drops=1) as s:
            c = segmatch.Client("127.0.0.1", s.port, retries=0)
            with self.assertRaises(ConnectionLost):
                c.info()
            self.assertEqual(s.connections, 1)
            with self.assertRaises(ConnectionLost, msg="broken stays broken without retries"):
                c.info()

    def test_a_broken_client_reconnects_on_its_next_call(self):
        with ScriptedServer(drops=2) as s:
            c = segmatch.Client("127.0.0.1", s.port)
            with self.assertRaises(ConnectionLost):
                c.ping(1)
            self.assertEqual(c.ping(2), 2, "the next call connects again")
            self.assertEqual(c.retries_used, 2)

    def test_connections_closed_before_hello_ok_do_not_spend_the_retry(self):
        # Connection 1 serves and drops the request; 2 and 3 are a dying replica's backlog.
        with ScriptedServer(drops=1, close_at_once=(2, 3)) as s:
            c = segmatch.Client("127.0.0.1", s.port)
            t0 = time.monotonic()
            self.assertEqual(c.ping(9), 9)
            self.assertEqual(s.connections, 4)
            self.assertEqual(c.retries_used, 1)
            self.assertGreaterEqual(time.monotonic() - t0, 0.05 + 0.1 - 0.01, "paused 50 ms, then 100 ms")

    def test_reconnecting_gives_up_after_the_window(self):
        with ScriptedServer(drops=1, close_at_once=range(2, 100)) as s:
            c = segmatch.Client("127.0.0.1", s.port, reconnect_window_s=0.3)
            t0 = time.monotonic()
            with self.assertRaises(ConnectionLost):
                c.ping(1)
            self.assertLess(time.monotonic() - t0, 2.0)
            self.assertEqual(s.requests("PING"), 1, "never sent to a server that did not answer HELLO")

    def test_an_error_reply_is_raised_with_its_code_and_not_retried(self):
        with ScriptedServer(error_code=ErrorCode.INTERNAL) as s:
            c = segmatch.Client("127.0.0.1", s.port)
            with self.assertRaises(ServerError) as ctx:
                c.localize(CLOUD)
            self.assertEqual(ctx.exception.code, ErrorCode.INTERNAL)
            self.assertEqual(int(ctx.exception.code), 12)
            self.assertEqual(ctx.exception.message, "scripted failure")
            self.assertEqual(s.requests("LOCALIZE"), 1)
            self.assertFalse(c.broken, "an ERROR leaves the connection usable")
            with self.assertRaises(ServerError):
                c.ping(1)
            self.assertEqual(s.connections, 1)

    def test_an_unknown_error_code_is_reported_by_number(self):
        with ScriptedServer(error_code=77) as s:
            with self.assertRaises(ServerError) as ctx:
                segmatch.Client("127.0.0.1", s.port).info()
            self.assertEqual(ctx.exception.code, 77)

    def test_a_timeout_is_not_retried(self):
        with ScriptedServer(silent=True) as s:
            c = segmatch.Client("127.0.0.1", s.port, timeout_s=0.3)
            t0 = time.monotonic()
            with self.assertRaises(ClientTimeout):
                c.localize(CLOUD)
            self.assertLess(time.monotonic() - t0, 2.0)
            self.assertEqual(s.requests("LOCALIZE"), 1)
            self.assertTrue(c.broken, "the reply may still come: the byte stream is lost")

    def test_a_mismatched_reply_is_a_protocol_error(self):
        with ScriptedServer(nonce_offset=1, id_offset=1) as s:
            c = segmatch.Client("127.0.0.1", s.port)
            with self.assertRaises(ProtocolError):
                c.ping(3)
            with self.assertRaises(ProtocolError):
                c.localize(CLOUD, request_id=4)
            self.assertEqual(s.requests("LOCALIZE"), 1, "not retried")

    def test_the_token_is_sent_in_hello_first(self):
        with ScriptedServer() as s:
            c = segmatch.Client("127.0.0.1", s.port, token="secret")
            self.assertEqual(c.info().map_name, "scripted")
            self.assertEqual(s.log, [(1, "HELLO"), (1, "INFO")])

    def test_nothing_listening_is_a_connect_error(self):
        with ScriptedServer() as s:
            port = s.port
        with self.assertRaises(ConnectError):
            segmatch.Client("127.0.0.1", port, connect_timeout_s=1)


class NewestScans(unittest.TestCase):
    """Revision 8: newest_points go behind FLAG_NEWEST_SCANS, x y z only; none sent, no flag."""

    def test_newest_points_are_sent_behind_their_flag(self):
        newest = np.arange(20, dtype=np.float64).reshape(5, 4)  # intensity dropped
        with ScriptedServer() as s, segmatch.Client("127.0.0.1", s.port) as c:
            c.localize(CLOUD, newest_points=newest, prior=Prior(np.eye(4), 5.0, 10.0))
            c.localize(CLOUD, newest_points=np.zeros((0, 3)))
            c.localize(CLOUD)
        sent = [m for m in s.received if isinstance(m, p.Localize)]
        self.assertEqual([bool(m.flags & p.FLAG_NEWEST_SCANS) for m in sent], [True, False, False])
        np.testing.assert_array_equal(sent[0].newest_points, newest[:, :3])
        self.assertEqual(sent[0].prior_heading_tolerance_deg, 10.0, "after the heading tolerance")
        self.assertEqual(sent[1].newest_points.shape, (0, 3))

    def test_a_server_of_revision_7_answers_malformed(self):
        with ScriptedServer(error_code=ErrorCode.MALFORMED) as s, segmatch.Client("127.0.0.1", s.port) as c:
            with self.assertRaises(ServerError) as ctx:
                c.localize(CLOUD, newest_points=CLOUD)
            self.assertEqual(ctx.exception.code, ErrorCode.MALFORMED)
            self.assertFalse(c.broken, "the connection is kept: resend without the newest scans")


class BadArguments(unittest.TestCase):
    """Bad input raises ValueError/TypeError naming the argument, and sends nothing."""

    @classmethod
    def setUpClass(cls):
        cls.server = ScriptedServer()
        cls.client = segmatch.Client("127.0.0.1", cls.server.port)

    @classmethod
    def tearDownClass(cls):
        cls.client.close()
        cls.server.close()

    def check(self, pattern, **kwargs):
        args = dict(points=CLOUD)
        args.update(kwargs)
        sent = len(self.server.log)
        with self.assertRaisesRegex((ValueError, TypeError), pattern):
            self.client.localize(**args)
        self.assertEqual(len(self.server.log), sent, "nothing sent")

    def test_points(self):
        self.check("shape", points=np.zeros((5, 5)))
        self.check("shape", points=np.zeros(12))
        self.check("finite", points=np.array([[0, 0, np.nan]]))
        self.check("finite in float32", points=np.array([[0, 0, 1e39]]))  # overflows float32
        self.check("numbers", points=np.array([["a", "b", "c"]]))
        self.check("newest_points must be an", newest_points=np.zeros((5, 5)))
        self.check("newest_points must be finite", newest_points=np.array([[0, np.inf, 0]]))

    def test_poses(self):
        self.check("w x y z", sensor_orientation=(1, 0, 0))
        self.check("norm", sensor_orientation=(0.5, 0, 0, 0))
        self.check("rotation", sensor_orientation=np.diag([1.0, 1.0, -1.0]))
        self.check("sensor_position", sensor_position=(0, np.inf, 0))
        self.check("4x4", T_local_sensor=np.eye(3))
        self.check("radius", prior=Prior(np.eye(4), -1.0))
        self.check("heading", prior=Prior(np.eye(4), 5.0, float("nan")))
        self.check("Prior", prior=np.eye(4))
        self.check("request_id", request_id=-1)
        with self.assertRaisesRegex(ValueError, "nonce"):
            self.client.ping(1 << 64)

    def test_good_input_of_every_form_is_accepted(self):
        r = self.client.localize(np.ones((3, 4)), sensor_orientation=np.eye(3), voxelized=True,
                                 prior=Prior(np.eye(4), 5.0, 10.0))
        self.assertEqual(r.reason, "scripted")
        self.assertFalse(self.client.broken)

    def test_client_options(self):
        for kwargs in (dict(retries=-1), dict(timeout_s=0), dict(connect_timeout_s=float("nan"))):
            with self.assertRaises(ValueError):
                segmatch.Client("127.0.0.1", self.server.port, **kwargs)


if __name__ == "__main__":
    unittest.main()
