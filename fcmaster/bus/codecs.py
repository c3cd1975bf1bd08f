"""The codec a line speaks, as the spec of its ``protocol`` builds it."""

from __future__ import annotations

from dataclasses import replace

from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.protocol.codec import DriveCodec, ParameterKey
from fcmaster.protocol.registry import spec_for


def codec_for(plan: LinePlan) -> DriveCodec:
    """A codec set up for ``plan``'s protocol and its protocol options."""
    nominal_hz = {drive.address: drive.nominal_frequency_hz for drive in plan.drives}
    profiles = {d.address: d.profile for d in plan.drives if d.profile is not None}
    return spec_for(plan.protocol).codec(plan, nominal_hz, profiles)


def monitor_keys(codec: DriveCodec, drive: DrivePlan) -> tuple[ParameterKey, ...]:
    """What ``drive``'s idle polls read: its monitor list, or the protocol's default one.

    UsageError for a parameter the codec does not know (the config check refuses it first).
    """
    if drive.monitor is None:
        return codec.default_monitor()
    return tuple(codec.parameter(text) for text in drive.monitor)


def with_protocol_delay(plan: LinePlan) -> LinePlan:
    """``plan`` with the response delay its protocol fixes, where it fixes one.

    Where the delay is each drive's own setting, the plan keeps the line's; where the
    protocol fixes it (a waiting time carried in the request plus the data check), the reply
    deadline must allow for that.
    """
    delay_s = spec_for(plan.protocol).response_delay_s(plan)
    return plan if delay_s is None else replace(plan, response_delay_s=delay_s)
