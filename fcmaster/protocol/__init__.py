"""Sans-I/O drive protocol codecs: bytes in, typed messages out, and back.

Every vendor package (``danfoss_fc``, ``mitsubishi``, ``enc``) offers a :class:`DriveCodec`:
it encodes each request as an :class:`Exchange` and decodes the drive's answer into a
:class:`Reply`, and its :class:`Framer` cuts the byte stream into :class:`Frame` and
:class:`Skipped` pieces. These types are all the bus knows of a vendor.

Each name is imported on first use (:mod:`fcmaster.lazy_face`): what needs only the registry
of protocol names does not load the codec types.
"""

from typing import TYPE_CHECKING

from fcmaster.lazy_face import lazy_face

if TYPE_CHECKING:
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

if not TYPE_CHECKING:
    __getattr__, __dir__ = lazy_face(
        __name__,
        __all__,
        {
            "fcmaster.protocol.codec": (
                "Access",
                "Condition",
                "ConditionReport",
                "DriveCodec",
                "DriveError",
                "DriveStatus",
                "Exchange",
                "ParameterKey",
                "ParameterValue",
                "Reply",
            ),
            "fcmaster.protocol.drive": ("ControlIntent", "Motion"),
            "fcmaster.protocol.framing": (
                "Frame",
                "Framer",
                "FramerBuffer",
                "SkipReason",
                "Skipped",
            ),
        },
    )
