"""Constants of the SGMQ protocol (docs/protocol.md): frame header, message types, LOCALIZE
flag bits, reply statuses. Re-exported by segmatch.protocol."""

from __future__ import annotations

import enum

MAGIC = b"SGMQ"
VERSION = 1  # the frame header's version
REVISION = 11  # the document's revision: additions since version 1 (docs/protocol.md 8)
HEADER_BYTES = 12
MAX_PAYLOAD_BYTES = 64 << 20  # the server's default --max-frame-mb

# LOCALIZE flag bits (docs/protocol.md 5.4).
FLAG_HAS_PRIOR = 1 << 0
FLAG_VOXELIZED = 1 << 1  # the points are centroids of the map's voxel grid
FLAG_PRIOR_HEADING = 1 << 2  # revision 2: the prior's heading tolerance follows the points
FLAG_REFUSAL_CODE = 1 << 3  # revision 5: the reply carries a RefusalCode (servers of revision <= 4: MALFORMED)
FLAG_DETAIL = 1 << 4  # revision 6: the reply carries a detail block (servers of revision <= 5: MALFORMED)
# Revision 8: the vehicle's newest scans follow the points (servers of revision <= 7: MALFORMED).
FLAG_NEWEST_SCANS = 1 << 5
FLAG_TRACK = 1 << 6  # revision 11: track on the surface layer first; needs FLAG_HAS_PRIOR and FLAG_NEWEST_SCANS
KNOWN_FLAGS = (FLAG_HAS_PRIOR | FLAG_VOXELIZED | FLAG_PRIOR_HEADING | FLAG_REFUSAL_CODE | FLAG_DETAIL | FLAG_NEWEST_SCANS
               | FLAG_TRACK)
LOCALIZE_FIXED_BYTES = 140  # payload bytes before the points


class MessageType(enum.IntEnum):
    HELLO = 0x0001
    PING = 0x0002
    INFO = 0x0003
    LOCALIZE = 0x0004
    LOCALIZE_SEGMENTS = 0x0005  # revision 3
    HELLO_OK = 0x8001  # replies have the high bit set
    PONG = 0x8002
    INFO_REPLY = 0x8003
    LOCALIZE_REPLY = 0x8004
    ERROR = 0x80FF


class RefusalCode(enum.IntEnum):
    """Why not localized (revision 5, docs/protocol.md 6.4); 0 unless the request set its
    refusal-code bit. A reply may carry a later revision's code: LocalizeReply.refusal is an int."""

    NONE = 0
    EMPTY_MAP = 1
    TOO_FEW_SEGMENTS = 2
    NO_CONSISTENT_MATCHES = 3
    OUTSIDE_PRIOR = 4
    LOW_SUPPORT = 5
    AMBIGUOUS = 6
    SURFACES_DISAGREE = 7
    LOW_CONFIDENCE = 8
    OFF_MAP = 9  # revision 9
    NEWEST_SCANS_DISAGREE = 10  # revision 9
    TRACKING_LOST = 11  # revision 11: a tracking request without segment points did not register


class LocalizeStatus(enum.IntEnum):
    LOCALIZED = 0
    NOT_LOCALIZED = 1
    OUTSIDE_PRIOR = 2  # a pose was found (and reported) but lies outside the prior's radius
