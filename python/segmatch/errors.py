"""Exceptions of the segmatch client and codec.

Mirrors the C++ client's ClientError kinds (api/include/segmatch/api/client.h) as classes, so a
caller can catch exactly what it can act on:

* ConnectError   -- no server could be reached (not retried by the client: nothing was sent).
* ClientTimeout  -- no (complete) reply in time; the server may still be working on it, so the
                    request is not re-sent, and the connection is dropped (its byte stream is lost).
* ConnectionLost -- the server closed or reset the connection before the whole reply came.
* ProtocolError  -- the reply did not decode or was not the expected message.
  DecodeError    -- a frame did not decode; .status names why, as the C++ codec's DecodeStatus.
* ServerError    -- the server answered ERROR; .code is the protocol's numeric code
                    (an ErrorCode when known, else the plain int: docs/protocol.md 8, rule 6).
"""

from __future__ import annotations

import enum


class ErrorCode(enum.IntEnum):
    """Codes of ERROR replies (docs/protocol.md section 7)."""

    BAD_MAGIC = 1
    UNSUPPORTED_VERSION = 2
    UNKNOWN_TYPE = 3
    MALFORMED = 4
    FRAME_TOO_LARGE = 5
    BAD_POINT_COUNT = 6
    NON_FINITE = 7
    BAD_QUATERNION = 8
    AUTH_REQUIRED = 9
    AUTH_FAILED = 10
    SERVER_BUSY = 11
    INTERNAL = 12
    UNEXPECTED_MESSAGE = 13
    SHUTTING_DOWN = 14
    PARAMETERS_MISMATCH = 15  # revision 3
    REQUEST_TIMEOUT = 16  # revision 4


def error_code(value: int):
    """The ErrorCode for a wire value, or the int itself for a code this client does not know.

    A newer server may send a code added after this client was written (rule 6 of
    docs/protocol.md 8 allows it); it is still a failed request, reported with its number."""
    try:
        return ErrorCode(value)
    except ValueError:
        return int(value)


class DecodeStatus(enum.Enum):
    """Why a frame did not decode; the same names and checks as the C++ codec's DecodeStatus."""

    INCOMPLETE = "incomplete frame"
    BAD_MAGIC = "bad magic (not an SGMQ frame)"
    BAD_VERSION = "unsupported protocol version"
    UNKNOWN_TYPE = "unknown or unexpected message type"
    TOO_LARGE = "payload over the size limit"
    TRUNCATED = "payload truncated"
    TRAILING_BYTES = "trailing bytes after the payload's fields"
    BAD_POINT_COUNT = "point count disagrees with the payload length"
    BAD_STRIDE = "point stride must be 3 or 4 floats"
    NON_FINITE = "NaN or Inf value"
    BAD_QUATERNION = "quaternion is not unit length"
    BAD_FIELD = "invalid field (reserved bits, string length or range)"

    @property
    def error_code(self) -> ErrorCode:
        """The ERROR code a server answers to a request that fails this way (error_code_for)."""
        return _ERROR_FOR_STATUS.get(self, ErrorCode.MALFORMED)


_ERROR_FOR_STATUS = {
    DecodeStatus.BAD_MAGIC: ErrorCode.BAD_MAGIC,
    DecodeStatus.BAD_VERSION: ErrorCode.UNSUPPORTED_VERSION,
    DecodeStatus.UNKNOWN_TYPE: ErrorCode.UNKNOWN_TYPE,
    DecodeStatus.TOO_LARGE: ErrorCode.FRAME_TOO_LARGE,
    DecodeStatus.BAD_POINT_COUNT: ErrorCode.BAD_POINT_COUNT,
    DecodeStatus.BAD_STRIDE: ErrorCode.BAD_POINT_COUNT,
    DecodeStatus.NON_FINITE: ErrorCode.NON_FINITE,
    DecodeStatus.BAD_QUATERNION: ErrorCode.BAD_QUATERNION,
}


class SegmatchError(Exception):
    """Base class of every error the client raises (bad arguments raise ValueError/TypeError)."""


class ConnectError(SegmatchError):
    """Could not connect to (or resolve) the server."""


class ClientTimeout(SegmatchError, TimeoutError):
    """No complete reply (or send) within the client's timeout."""


class ConnectionLost(SegmatchError, ConnectionError):
    """The server closed or reset the connection before the reply was complete."""


class ProtocolError(SegmatchError):
    """The peer sent something that is not a valid reply of the protocol."""


class DecodeError(ProtocolError):
    """A frame or payload did not decode. .status is a DecodeStatus."""

    def __init__(self, status: DecodeStatus, detail: str = ""):
        self.status = status
        super().__init__(status.value + (": " + detail if detail else ""))


class ServerError(SegmatchError):
    """The server answered ERROR. .code: ErrorCode (or int if unknown), .message: its text."""

    def __init__(self, code, message: str, where: str = ""):
        self.code = error_code(int(code))
        self.message = message
        name = self.code.name if isinstance(self.code, ErrorCode) else "unknown code"
        prefix = where + ": " if where else ""
        super().__init__(f"{prefix}server error {int(self.code)} ({name}): {message}")
