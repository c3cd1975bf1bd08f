"""The MQTT bridge's topics and payloads (DESIGN.md "MQTT"), and when a state is worth sending.

Every drive has five topics under the base, named by its line and its name::

    {base}/{bus}/{drive}/state            retained Drive state JSON (DESIGN.md "Drive state")
    {base}/{bus}/{drive}/availability     retained "online" | "offline"
    {base}/{bus}/{drive}/event            {"event": "alarm_raised", "code": …, "text": …, …}
    {base}/{bus}/{drive}/command          JSON command with an "id" (from the plant)
    {base}/{bus}/{drive}/command/result   {"id": …, "outcome": …, "reason": …, …}

and the gateway has ``{base}/status`` (retained "online", "offline" as its last will).

State goes out when it changes *significantly*: any change of a discrete field (online,
running, fault, warning, direction, at_reference, status word, commanded reference, alarms,
warnings, the set of values), or an analog value moving by more than the deadband since the
state last *sent* — output frequency in % of the drive's nominal frequency, every other value
in % of its reading — so slow drifts add up and are sent once they cross it. The heartbeat
sends every state anyway, with its fresh ``updated_at``.
"""

from __future__ import annotations

import json
from typing import Any

from fcmaster.bus.commands import CommandResult
from fcmaster.state import DriveState

ONLINE = b"online"
OFFLINE = b"offline"


class Topics:
    """Topic names under one base."""

    def __init__(self, base: str, status: str | None = None) -> None:
        """Topics under ``base``; the gateway's status on ``status`` (default {base}/status)."""
        self.base = base
        self.status = status or f"{base}/status"

    def drive(self, bus: str, drive: str, leaf: str) -> str:
        """``{base}/{bus}/{drive}/{leaf}``."""
        return f"{self.base}/{bus}/{drive}/{leaf}"

    def state(self, bus: str, drive: str) -> str:
        """Where a drive's retained state goes."""
        return self.drive(bus, drive, "state")

    def availability(self, bus: str, drive: str) -> str:
        """Where a drive's retained online/offline goes."""
        return self.drive(bus, drive, "availability")

    def event(self, bus: str, drive: str) -> str:
        """Where a drive's events go."""
        return self.drive(bus, drive, "event")

    def command(self, bus: str, drive: str) -> str:
        """Where commands for a drive come in."""
        return self.drive(bus, drive, "command")

    def result(self, bus: str, drive: str) -> str:
        """Where the results of a drive's commands go."""
        return self.drive(bus, drive, "command/result")

    def commands(self, bus: str) -> str:
        """The subscription that takes commands for every drive on ``bus``."""
        return f"{self.base}/{bus}/+/command"

    def parse_command(self, topic: str) -> tuple[str, str] | None:
        """``(bus, drive)`` of a command topic, or None when ``topic`` is not one."""
        prefix, suffix = f"{self.base}/", "/command"
        if not (topic.startswith(prefix) and topic.endswith(suffix)):
            return None
        bus, slash, drive = topic[len(prefix) : -len(suffix)].partition("/")
        if not slash or not bus or not drive or "/" in drive:
            return None
        return bus, drive


def encode(payload: dict[str, Any]) -> bytes:
    """Compact UTF-8 JSON."""
    return json.dumps(payload, separators=(",", ":"), ensure_ascii=False).encode()


def result_payload(
    command_id: Any, bus: str, drive: str, action: str | None, result: CommandResult
) -> bytes:
    """A command's result: its ``id`` first, then where, what, and DESIGN.md's result JSON."""
    return encode(
        {"id": command_id, "bus": bus, "drive": drive, "action": action, **result.to_json()}
    )


def event_payload(event: str, bus: str, drive: str, at: str | None, **facts: Any) -> bytes:
    """An event: ``{"event": …, "bus": …, "drive": …, "at": …, **facts}``."""
    return encode({"event": event, "bus": bus, "drive": drive, "at": at, **facts})


def is_significant(
    sent: DriveState, new: DriveState, *, deadband_pct: float, nominal_frequency_hz: float
) -> bool:
    """Whether ``new`` differs enough from the state last ``sent`` to be sent now."""
    if (
        sent.online != new.online
        or sent.running != new.running
        or sent.fault != new.fault
        or sent.warning != new.warning
        or sent.direction != new.direction
        or sent.at_reference != new.at_reference
        or sent.status_word != new.status_word
        or sent.reference_pct != new.reference_pct
        or sent.control != new.control
        or sent.alarms != new.alarms
        or sent.warnings != new.warnings
        or sent.values.keys() != new.values.keys()
    ):
        return True
    band = deadband_pct / 100.0
    old_hz, new_hz = sent.output_frequency_hz, new.output_frequency_hz
    if (old_hz is None) != (new_hz is None):
        return True
    if (
        old_hz is not None
        and new_hz is not None
        and abs(new_hz - old_hz) > band * abs(nominal_frequency_hz)
    ):
        return True
    for name, measured in new.values.items():
        old, value = sent.values[name].value, measured.value
        if isinstance(old, str) or isinstance(value, str):
            if old != value:
                return True
        elif abs(value - old) > band * max(abs(value), abs(old)):
            return True
    return False
