"""Shared by the Python client's tests: paths, a scripted loopback server, a real server process.

Paths come from the environment so CTest (tests/python/run.sh) can pass them:
  SEGMATCH_SOURCE_DIR  the repository (default: two levels above this file)
  SEGMATCH_BIN_DIR     the C++ build's bin folder (default: SOURCE/build/bin)
"""

from __future__ import annotations

import os
import re
import socket
import subprocess
import threading
import time
from pathlib import Path

from segmatch import protocol as p

SOURCE_DIR = Path(os.environ.get("SEGMATCH_SOURCE_DIR", Path(__file__).resolve().parents[2]))
BIN_DIR = Path(os.environ.get("SEGMATCH_BIN_DIR", SOURCE_DIR / "build" / "bin"))
# Set by CTest: the binaries must be there, a missing one is a failure rather than a skip.
BIN_DIR_REQUIRED = "SEGMATCH_BIN_DIR" in os.environ
PROTOCOL_DATA = SOURCE_DIR / "tests" / "data" / "protocol"
GOLDEN_V1_V4 = SOURCE_DIR / "tests" / "api" / "golden"


def read_frame(sock: socket.socket):
    """One whole frame from a blocking socket: (Header, payload), or None when it closed first."""
    def exact(n):
        buf = b""
        while len(buf) < n:
            chunk = sock.recv(n - len(buf))
            if not chunk:
                return None
            buf += chunk
        return buf
    head = exact(p.HEADER_BYTES)
    if head is None:
        return None
    header = p.decode_header(head)
    payload = exact(header.payload_bytes)
    return None if payload is None else (header, payload)


class ScriptedServer:
    """A loopback server playing the failures the client's retry policy is about (as the C++
    tests/api/client_retry_test.cpp). Connections numbered (from 1) in close_at_once are closed
    before anything is read, like a dying replica's backlog. Others answer HELLO with HELLO_OK;
    then, while `drops` lasts, a request closes the connection unanswered; `silent` never answers
    requests; otherwise PING -> PONG (nonce + nonce_offset), INFO -> INFO_REPLY, LOCALIZE ->
    LOCALIZE_REPLY (id + id_offset) or, with error_code, ERROR."""

    def __init__(self, drops=0, close_at_once=(), silent=False, error_code=None, nonce_offset=0, id_offset=0):
        self.drops, self.close_at_once, self.silent = drops, set(close_at_once), silent
        self.error_code, self.nonce_offset, self.id_offset = error_code, nonce_offset, id_offset
        self.connections = 0
        self.log = []  # (connection number, MessageType name) of every frame read
        self.received = []  # the decoded messages, as log
        self._lock = threading.Lock()
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port = self._listener.getsockname()[1]
        self._threads = [threading.Thread(target=self._accept, daemon=True)]
        self._threads[0].start()

    def requests(self, name: str) -> int:
        with self._lock:
            return sum(1 for _, n in self.log if n == name)

    def close(self) -> None:
        # shutdown first: close() alone leaves a thread blocked in accept() holding the port open.
        try:
            self._listener.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._listener.close()
        self._threads[0].join(5)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self._listener.accept()
            except OSError:
                return
            with self._lock:
                self.connections += 1
                number = self.connections
            if number in self.close_at_once:
                conn.close()
                continue
            t = threading.Thread(target=self._serve, args=(conn, number), daemon=True)
            t.start()

    def _serve(self, conn: socket.socket, number: int) -> None:
        with conn:
            conn.settimeout(10)
            while True:
                try:
                    frame = read_frame(conn)
                except OSError:
                    return
                if frame is None:
                    return
                header, payload = frame
                message = p.decode_payload(header.type, payload)
                with self._lock:
                    self.log.append((number, p.MessageType(header.type).name))
                    self.received.append(message)
                    drop = not isinstance(message, p.Hello) and self.drops > 0
                    self.drops -= drop
                if drop:
                    return
                if self.silent and not isinstance(message, p.Hello):
                    time.sleep(5)  # longer than any client timeout in the tests
                    return
                conn.sendall(p.encode(self._answer(message)))

    def _answer(self, m):
        if isinstance(m, p.Hello):
            return p.HelloOk()
        if self.error_code is not None:
            return p.Error(self.error_code, "scripted failure")
        if isinstance(m, p.Ping):
            return p.Pong(m.nonce + self.nonce_offset)
        if isinstance(m, p.Info):
            return p.InfoReply(map_name="scripted")
        return p.LocalizeReply(request_id=m.request_id + self.id_offset, reason="scripted")


class ServerProcess:
    """build/bin/segmatch-server on an ephemeral loopback port; stopped with SIGTERM on exit."""

    def __init__(self, map_path: Path, *extra_args: str, log_path: Path):
        binary = BIN_DIR / "segmatch-server"
        self.log_path = log_path
        self._log = open(log_path, "w")
        self.proc = subprocess.Popen([str(binary), "--map", str(map_path), "--port", "0", "--workers", "2",
                                      "--stats-interval-s", "0", *extra_args],
                                     stdout=self._log, stderr=subprocess.STDOUT)
        self.port = self._wait_for_port()

    def _wait_for_port(self, timeout_s: float = 60.0) -> int:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            m = re.search(r"listening on [0-9.]+:(\d+)", self.log_path.read_text())
            if m:
                return int(m.group(1))
            if self.proc.poll() is not None:
                raise RuntimeError(f"segmatch-server exited {self.proc.returncode}:\n{self.log_path.read_text()}")
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"segmatch-server did not listen within {timeout_s} s:\n{self.log_path.read_text()}")

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()
        return self.proc.returncode

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()
