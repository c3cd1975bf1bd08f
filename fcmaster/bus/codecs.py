"""The codec a line speaks, chosen by its ``protocol`` id."""

from __future__ import annotations

from dataclasses import replace

from fcmaster.bus.plan import LinePlan
from fcmaster.errors import UsageError
from fcmaster.protocol.codec import DriveCodec
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.danfoss_fc.telegram import AddressFormat
from fcmaster.protocol.enc.codec import EncCodec
from fcmaster.protocol.mitsubishi.codec import MitsubishiCodec, answer_delay_s

PROTOCOLS = ("danfoss-fc", "mitsubishi", "enc")


def codec_for(plan: LinePlan) -> DriveCodec:
    """A codec set up for ``plan``'s protocol and its protocol options."""
    if plan.protocol == "danfoss-fc":
        return FcCodec(
            AddressFormat(plan.address_format),
            # The main actual value is in % of the drive's nominal; replies carry Hz.
            nominal_hz={drive.address: drive.nominal_frequency_hz for drive in plan.drives},
        )
    if plan.protocol == "mitsubishi":
        return MitsubishiCodec(
            terminator=plan.terminator,
            wait_time_ms=plan.wait_time_ms,
            # Frequencies travel in 0.01 Hz: the drive's nominal says what 100 % is.
            nominal_hz={drive.address: drive.nominal_frequency_hz for drive in plan.drives},
        )
    if plan.protocol == "enc":
        return EncCodec(
            address_encoding=plan.address_encoding,
            response_encoding=plan.response_encoding,
            fault_encoding=plan.fault_encoding,
            # ENC frames carry frequencies in Hz: the drive's nominal says what 100 % is.
            nominal_hz={drive.address: drive.nominal_frequency_hz for drive in plan.drives},
        )
    raise UsageError(f"protocol {plan.protocol!r} is not supported")


def with_protocol_delay(plan: LinePlan) -> LinePlan:
    """``plan`` with the response delay its protocol fixes, where it fixes one.

    An FC drive's delay is its own setting (8-35), so an FC plan stays as it is. Mitsubishi
    drives wait the waiting time, then check the data (up to 30 ms for a parameter), so the
    reply deadline must allow for both.
    """
    if plan.protocol == "mitsubishi":
        return replace(plan, response_delay_s=answer_delay_s(plan.wait_time_ms))
    return plan
