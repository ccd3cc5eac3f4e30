"""segmatch: a pure-Python client of segmatch-server (docs/protocol.md).

    import numpy as np, segmatch
    with segmatch.Client("127.0.0.1", 7878) as c:
        reply = c.localize(points_xyz, T_local_sensor=T)      # points: (N, 3) or (N, 4) float32
        if reply.status == segmatch.LocalizeStatus.LOCALIZED:
            T_map_sensor = reply.T_map_local @ T                # 4x4 matrices

Quaternions on the wire and in this API are **w x y z**; ROS uses x y z w
(segmatch.wxyz_from_ros_xyzw converts).
"""

from . import protocol
from .client import Client, Prior
from .errors import (ClientTimeout, ConnectError, ConnectionLost, DecodeError, DecodeStatus, ErrorCode, ProtocolError,
                     SegmatchError, ServerError)
from .pose import Pose, ros_xyzw_from_wxyz, wxyz_from_ros_xyzw
from .protocol import InfoReply, LocalizeReply, LocalizeStatus, RefusalCode, Timings

__version__ = "0.1.0"

__all__ = ["Client", "Prior", "Pose", "InfoReply", "LocalizeReply", "LocalizeStatus", "RefusalCode", "Timings", "ErrorCode",
           "DecodeStatus", "SegmatchError", "ConnectError", "ClientTimeout", "ConnectionLost", "ProtocolError",
           "DecodeError", "ServerError", "wxyz_from_ros_xyzw", "ros_xyzw_from_wxyz", "protocol"]
