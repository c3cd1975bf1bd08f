"""A drive's snapshot: the frozen state every surface shows (DESIGN.md "Drive state").

:class:`DriveState` is immutable, so readers keep a reference without copying or locking;
the fleet state (``fcmaster.state``) makes a new one when a reply changes something.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from fcmaster.bus.watchdog import WatchdogReport
from fcmaster.protocol.codec import Condition
from fcmaster.protocol.registry import PROTOCOLS


@dataclass(slots=True, frozen=True)
class Measured:
    """One measured or read value, with the manual's name and the time it was read."""

    value: float | str
    unit: str
    raw: int | None = None
    name: str = ""  # the manual's name ("Motor Current"); "" when the codec does not know it
    updated_at: float | None = None  # wall-clock seconds of the reply that carried it
    # An alarm or warning word: the texts of the conditions it shows (None: not such a word)
    texts: tuple[str, ...] | None = None

    def to_json(self) -> dict[str, Any]:
        """``{"value", "unit", "name", "updated_at"}``, and ``texts`` for a condition word."""
        out: dict[str, Any] = {
            "value": self.value,
            "unit": self.unit,
            "name": self.name,
            "updated_at": rfc3339(self.updated_at),
        }
        if self.texts is not None:
            out["texts"] = list(self.texts)
        return out


@dataclass(slots=True, frozen=True, kw_only=True)
class DriveState:
    """One drive as the gateway knows it now (DESIGN.md "Drive state")."""

    name: str
    bus: str
    address: int
    protocol: str
    control: str  # "bus" | "monitor"
    online: bool = False
    running: bool = False
    fault: bool = False
    warning: bool = False
    direction: str = "forward"
    at_reference: bool = False
    output_frequency_hz: float | None = None
    # When the output frequency was read: Mitsubishi and ENC read it in an exchange of its
    # own, so it can be older than the status beside it (never presented as newer).
    output_frequency_updated_at: float | None = None
    reference_pct: float | None = None  # what the master commands; None when it commands nothing
    status_word: int | None = None
    values: dict[str, Measured] = field(default_factory=dict)
    alarms: tuple[Condition, ...] = ()
    warnings: tuple[Condition, ...] = ()
    updated_at: float | None = None  # wall-clock seconds of the last good reply
    # control: bus drives: their own communication watchdog as last read and judged (None
    # until the watchdog audit first reports, soon after the drive is first adopted)
    watchdog: WatchdogReport | None = None

    @property
    def key(self) -> str:
        """``bus/name``, unique in the fleet."""
        return f"{self.bus}/{self.name}"

    @property
    def status_bits(self) -> list[str]:
        """The names of the status word's set bits, as the protocol's manual names them."""
        # For people: the normalised flags beside it are what programs should use.
        spec = PROTOCOLS.get(self.protocol)
        if spec is None or self.status_word is None:
            return []
        flags = spec.status_bits
        return [str(f.name).lower() for f in flags if f.value and self.status_word & f.value]

    def to_json(self) -> dict[str, Any]:
        """The public JSON shape shown on every surface."""
        out: dict[str, Any] = {
            "name": self.name,
            "bus": self.bus,
            "address": self.address,
            "protocol": self.protocol,
            "online": self.online,
            "control": self.control,
            "running": self.running,
            "fault": self.fault,
            "warning": self.warning,
            "direction": self.direction,
            "at_reference": self.at_reference,
            # A reply's exact step (FC: 1/16384 of nominal) shown to the 0.001 Hz people read.
            "output_frequency_hz": _hz(self.output_frequency_hz),
            "output_frequency_updated_at": rfc3339(self.output_frequency_updated_at),
            "reference_pct": self.reference_pct,
            "status_word": self.status_word,
            "status_bits": self.status_bits,
            "values": {name: m.to_json() for name, m in self.values.items()},
            "alarms": [{"code": c.code, "text": c.text} for c in self.alarms],
            "warnings": [{"code": c.code, "text": c.text} for c in self.warnings],
            "updated_at": rfc3339(self.updated_at),
        }
        if self.watchdog is not None:
            out["watchdog"] = self.watchdog.to_json()
        return out


def rfc3339(wall: float | None) -> str | None:
    """Wall-clock seconds as RFC 3339 UTC with milliseconds, e.g. 2026-11-22T08:00:00.123Z."""
    if wall is None:
        return None
    return datetime.fromtimestamp(wall, UTC).isoformat(timespec="milliseconds")[:-6] + "Z"


def _hz(value: float | None) -> float | None:
    return None if value is None else round(value, 3)
