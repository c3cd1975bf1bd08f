"""Sans-I/O drive protocol codecs: bytes in, typed messages out, and back.

Every vendor package (``danfoss_fc``, ``mitsubishi``, ``enc``) offers a :class:`DriveCodec`:
it encodes each request as an :class:`Exchange` and decodes the drive's answer into a
:class:`Reply`, and its :class:`Framer` cuts the byte stream into :class:`Frame` and
:class:`Skipped` pieces. These types are all the bus knows of a vendor.
"""

from fcmaster.protocol.codec import (
    Access,
    Condition,
    ConditionReport,
    DriveCodec,
    DriveError,
    DriveStatus,
    Exchange,
    ParameterKey,
    ParameterValue,
    Reply,
)
from fcmaster.protocol.drive import ControlIntent, Motion
from fcmaster.protocol.framing import Frame, Framer, FramerBuffer, Skipped, SkipReason

__all__ = [
    "Access",
    "Condition",
    "ConditionReport",
    "ControlIntent",
    "DriveCodec",
    "DriveError",
    "DriveStatus",
    "Exchange",
    "Frame",
    "Framer",
    "FramerBuffer",
    "Motion",
    "ParameterKey",
    "ParameterValue",
    "Reply",
    "SkipReason",
    "Skipped",
]
