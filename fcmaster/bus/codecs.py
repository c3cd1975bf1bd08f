"""The codec a line speaks, chosen by its ``protocol`` id."""

from __future__ import annotations

from fcmaster.bus.plan import LinePlan
from fcmaster.errors import UsageError
from fcmaster.protocol.codec import DriveCodec
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.danfoss_fc.telegram import AddressFormat

PROTOCOLS = ("danfoss-fc", "mitsubishi", "enc")


def codec_for(plan: LinePlan) -> DriveCodec:
    """A codec set up for ``plan``'s protocol and its protocol options."""
    if plan.protocol == "danfoss-fc":
        return FcCodec(AddressFormat(plan.address_format))
    raise UsageError(f"protocol {plan.protocol!r} is not supported yet (danfoss-fc is)")
