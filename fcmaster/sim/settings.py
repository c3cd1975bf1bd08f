"""How a simulated line and its drives start out: plain frozen data, for every vendor.

A vendor's simulated drive reads what it understands from :class:`DriveSettings`: the
motor, the load, its response delay, and parameter values written the way its manual
writes them (``{"3-41": 5.0}`` for an FC drive, in the parameter's unit). The YAML config
will map a bus's ``simulation:`` section onto these.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.registry import DEFAULT, PROTOCOLS
from fcmaster.protocol.spec import OptionPairs
from fcmaster.sim.faults import FaultPlan
from fcmaster.sim.motor import Motor, MotorRating

SPIN_UP_S: Final = 120.0  # how long before power-up a drive found running was started


@dataclass(slots=True, frozen=True, kw_only=True)
class DriveSettings:
    """One simulated drive's starting point (vendor-neutral)."""

    response_delay_s: float | None = None  # None: the vendor's factory setting
    rating: MotorRating = field(default_factory=MotorRating)
    load: float = 0.7  # load torque at rated speed, fraction of rated torque
    load_exponent: float = 2.0  # 2: pump or fan; 0: constant torque
    reference_100_hz: float | None = None  # what 100 % reference means (FC: 3-03)
    max_frequency_hz: float | None = None  # the output's upper limit (FC: 4-14)
    parameters: Mapping[str, float] = field(default_factory=dict)  # manual notation → value
    faults: FaultPlan | None = None  # what goes wrong with this drive's replies
    local: bool = False  # in local (hand) operation: ignores bus commands
    interlocked: bool = False  # acknowledges a start but does not turn (no run enable)
    running_hz: float | None = None  # already running at power-up, as a former master left it
    warning_cycle: tuple[int, float, float] | None = None  # (warning number, every_s, for_s)
    # modbus-rtu: the drive profile it follows (a built-in's name or a DriveProfile; None:
    # the built-ins in turn by address)
    profile: object = None

    def started_at(self, now: float) -> float:
        """When the motor was started, for a drive powered up at ``now``.

        A drive found running (``running_hz``) was started long before, so it is already at
        speed when the master first sees it.
        """
        return now - SPIN_UP_S if self.running_hz else now

    def motor(self, started: float, rating: MotorRating | None = None) -> Motor:
        """The drive's motor and load (``rating`` where the vendor derives its own)."""
        motor = Motor(
            rating or self.rating, started, load=self.load, load_exponent=self.load_exponent
        )
        motor.interlocked = self.interlocked
        return motor

    def warning_showing(self, since_power_up_s: float) -> bool:
        """Whether the recurring warning (``warning_cycle``) shows at this age (False: none)."""
        if self.warning_cycle is None:
            return False
        _, every_s, for_s = self.warning_cycle
        return since_power_up_s % every_s < for_s


@dataclass(slots=True, frozen=True, kw_only=True)
class LineSettings:
    """A simulated line: protocol, character format and line-wide faults."""

    name: str = "line1"
    protocol: str = DEFAULT  # a registered protocol's name (fcmaster.protocol.registry)
    baudrate: int = 19200
    parity: str = "E"  # N | E | O
    stopbits: int = 1
    databits: int = 8
    faults: FaultPlan = field(default_factory=FaultPlan)
    # The protocol's line keys the simulated drives take (LineKey.simulated), as (key,
    # value) pairs; a key left out takes the spec's default (ProtocolSpec.options_of).
    protocol_options: OptionPairs = ()
    # a USB adapter's latency timer between the line and the master (None: none, as a pty)
    adapter_latency_ms: float | None = None
    # repeated addresses are drives that both answer (a replaced drive left at the old one's)
    duplicate_addresses: bool = False

    def __post_init__(self) -> None:
        if self.adapter_latency_ms is not None and not 0 < self.adapter_latency_ms <= 255:
            raise UsageError("an adapter's latency timer is 1-255 ms (FTDI allows 1-255)")
        if self.parity not in ("N", "E", "O"):
            raise UsageError(f"parity {self.parity!r} is not N, E or O")
        if self.protocol in PROTOCOLS:  # an unknown one is refused when the line is built
            problems = PROTOCOLS[self.protocol].option_problems(
                self.protocol_options, simulated=True
            )
            if problems:
                raise UsageError("; ".join(problems))
        if self.stopbits not in (1, 2) or self.databits not in (7, 8) or self.baudrate <= 0:
            raise UsageError("stop bits are 1 or 2, data bits 7 or 8, baud rate positive")

    @property
    def char_bits(self) -> int:
        """Bits per character on the wire: start, data, parity (unless N), stop."""
        return 1 + self.databits + (self.parity != "N") + self.stopbits
