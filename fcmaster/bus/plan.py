"""What a BusMaster is told about its line and drives: plain frozen data, no pydantic.

``fcmaster.config`` validates the YAML and hands these down; tests build them directly.
Timing helpers live here because the config check, the planner and the benchmarks all
derive the same figures from the same character format.
"""

from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass, field
from typing import Any

from fcmaster.protocol.registry import DEFAULT
from fcmaster.protocol.spec import OptionPairs


class OnStart(enum.StrEnum):
    """How the master takes a ``control: bus`` drive over."""

    ADOPT = "adopt"  # learn the drive's state first and command exactly that
    STOP = "stop"  # command a stop from the first telegram


@dataclass(slots=True, frozen=True)
class WatchdogPlan:
    """The communication watchdog a drive is to be given at adoption (config ``watchdog``)."""

    timeout_s: float
    action: str  # one of the protocol's actions ("stop", "trip")


@dataclass(slots=True, frozen=True, kw_only=True)
class DrivePlan:
    """One drive on a line."""

    name: str
    address: int
    control: bool = False  # True: `control: bus`; False: monitor only, never commanded
    on_start: OnStart = OnStart.ADOPT
    monitor: tuple[str, ...] | None = None  # None: the protocol's default list
    nominal_frequency_hz: float = 50.0  # what 100 % reference means
    min_frequency_hz: float = 0.0
    max_frequency_hz: float = 50.0
    # how long the status may take to show a start's or stop's result (None: a default)
    confirm_s: float | None = None
    watchdog: WatchdogPlan | None = None  # None: read and judged, never written
    # The drive's profile where its protocol has them (modbus-rtu: a DriveProfile, built-in
    # or read from the config's profile file); handed to the line's codec by address.
    profile: object = None


@dataclass(slots=True, frozen=True, kw_only=True)
class LinePlan:
    """One RS-485 line: its port, character format, timing policy and drives."""

    name: str
    port: str
    protocol: str = DEFAULT  # a registered protocol's name (fcmaster.protocol.registry)
    baudrate: int = 19200
    parity: str = "E"  # N | E | O
    stopbits: int = 1
    databits: int = 8
    address_format: int = 126  # a protocol's own line key (ProtocolSpec.line_keys): 31 | 126
    timeout_s: float | None = None  # None: derived from baud and reply length
    retries: int = 1  # extra attempts for a command
    pause_s: float | None = None  # None: the protocol's own minimum (codec.min_pause_s)
    response_delay_s: float = 0.010  # the slowest drive's answer delay (FC 8-35)
    offline_after: int = 3  # consecutive failures that demote a drive
    probe_interval_s: float = 5.0  # how often a demoted drive is probed (at most)
    probe_share: float = 0.08  # the most of the line's time probes may take while drives answer
    echo: bool = False  # the adapter hears its own transmission
    rs485: bool = False  # kernel RS-485 mode (RTS drives the transmitter)
    # More protocols' own line keys, named as in the config; their specs say what they mean.
    terminator: str = "cr"  # none | cr | crlf
    wait_time_ms: int | None = 0  # None: requests leave the waiting time out
    address_encoding: str = "hex"  # hex | decimal
    response_encoding: str = "hex"
    fault_encoding: str = "hex"
    # (key, value) of the line keys of protocols that have no field above; a protocol's
    # spec reads its options from the fields and these (ProtocolSpec.options_of)
    protocol_options: tuple[tuple[str, int | str | None], ...] = ()
    drives: tuple[DrivePlan, ...] = field(default=())

    @property
    def char_bits(self) -> int:
        """Bits per character: start, data, parity, stop."""
        return 1 + self.databits + (self.parity != "N") + self.stopbits

    @property
    def char_s(self) -> float:
        """Seconds one character takes on the wire."""
        return self.char_bits / self.baudrate

    def wire_s(self, length: int) -> float:
        """Seconds ``length`` characters take on the wire."""
        # char_bits spelt out: this runs several times a transaction
        bits = 1 + self.databits + (self.parity != "N") + self.stopbits
        return length * bits / self.baudrate

    def reply_timeout(self, request_length: int, reply_length: int) -> float:
        """Seconds from writing a request to giving up on its reply."""
        if self.timeout_s is not None:
            return self.timeout_s
        return self.wire_s(request_length + reply_length) + self.response_delay_s + 0.050

    @property
    def gap_s(self) -> float:
        """An inter-character gap this long ends a frame (3.5 characters, at least 2 ms).

        The floor covers USB adapters, which deliver bytes in batches a millisecond apart.
        """
        return max(3.5 * self.char_s, 0.002)

    def late_reply_s(self, reply_length: int) -> float:
        """After a reply's deadline, how long a late reply may still keep the line busy."""
        return self.wire_s(reply_length) + self.gap_s

    def miss_s(self, request_length: int, reply_length: int) -> float:
        """What an unanswered request costs the line: its deadline, then a late reply's time."""
        return self.reply_timeout(request_length, reply_length) + self.late_reply_s(reply_length)


def with_protocol_options(plan: LinePlan, pairs: OptionPairs) -> LinePlan:
    """``plan`` carrying a protocol's own line keys ``pairs``.

    Each goes to the plan's field of the same name where it has one, else among its
    ``protocol_options``, so a protocol whose keys have no field here needs none.
    """
    # values of the spec's keys (its LineKeys say what each may be), typed as the spec's
    fields: dict[str, Any] = {name: value for name, value in pairs if name in _FIELDS}
    extra = tuple((name, value) for name, value in pairs if name not in _FIELDS)
    return dataclasses.replace(plan, **fields, protocol_options=plan.protocol_options + extra)


_FIELDS = frozenset(f.name for f in dataclasses.fields(LinePlan))
