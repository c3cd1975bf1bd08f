"""What a BusMaster is told about its line and drives: plain frozen data, no pydantic.

``fcmaster.config`` validates the YAML and hands these down; tests build them directly.
Timing helpers live here because the config check, the planner and the benchmarks all
derive the same figures from the same character format.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field


class OnStart(enum.StrEnum):
    """How the master takes a ``control: bus`` drive over."""

    ADOPT = "adopt"  # learn the drive's state first and command exactly that
    STOP = "stop"  # command a stop from the first telegram


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


@dataclass(slots=True, frozen=True, kw_only=True)
class LinePlan:
    """One RS-485 line: its port, character format, timing policy and drives."""

    name: str
    port: str
    protocol: str = "danfoss-fc"
    baudrate: int = 19200
    parity: str = "E"  # N | E | O
    stopbits: int = 1
    databits: int = 8
    address_format: int = 126  # danfoss-fc only
    timeout_s: float | None = None  # None: derived from baud and reply length
    retries: int = 1  # extra attempts for a command
    pause_s: float | None = None  # None: the protocol's own minimum (codec.min_pause_s)
    response_delay_s: float = 0.010  # the slowest drive's answer delay (FC 8-35)
    offline_after: int = 3  # consecutive failures that demote a drive
    probe_interval_s: float = 5.0  # how often a demoted drive is probed (at most)
    probe_share: float = 0.1  # the most of the line's time probes may take while drives answer
    echo: bool = False  # the adapter hears its own transmission
    rs485: bool = False  # kernel RS-485 mode (RTS drives the transmitter)
    terminator: str = "cr"  # mitsubishi: none | cr | crlf, as the drives' Pr.124
    # mitsubishi: the waiting time each request carries (drives at Pr.123 = 9999, the
    # factory setting); None = requests leave it out because the drives' Pr.123 sets it
    wait_time_ms: int | None = 0
    # enc: how the drives write addresses ≥ 10, response codes and fault codes (hex | decimal)
    address_encoding: str = "hex"
    response_encoding: str = "hex"
    fault_encoding: str = "hex"
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
