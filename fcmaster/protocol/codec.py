"""The one interface every vendor codec offers the bus, and the vendor-neutral replies.

The bus master never branches on the vendor. It asks a :class:`DriveCodec` for the
:class:`Exchange` that carries an idle poll, a control change or a parameter access to one
drive, puts ``exchange.request`` on the wire, and hands the checked reply frame back to
:meth:`DriveCodec.parse`, which turns it into a :class:`Reply` in vendor-neutral terms. All
vendor knowledge — framing, checksums, bit layouts, parameter numbering, scaling, which
instruction a poll reads — stays behind this seam, in the protocol package.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Protocol

from fcmaster.protocol.drive import ControlIntent
from fcmaster.protocol.framing import Framer


class Access(enum.Enum):
    """What an exchange does with a parameter."""

    NONE = "none"
    READ = "read"
    WRITE = "write"


@dataclass(slots=True, frozen=True)
class ParameterKey:
    """A parameter as the user writes it (``name``) and as the codec addresses it (``code``)."""

    name: str
    code: int


@dataclass(slots=True, frozen=True, kw_only=True)
class Exchange:
    """One transaction: a request and what its reply must look like."""

    address: int  # 0 = broadcast
    request: bytes
    reply_length: int  # bytes of the expected reply on the wire; 0 = no reply comes
    access: Access = Access.NONE
    parameter: ParameterKey | None = None
    index: int = 0
    carries_control: bool = False  # the request commands the drive (FC: CTW bit 10 = 1)
    # The drive restarts on this request (an inverter reset): its output goes off and it
    # hears nothing for this many seconds, so it must not be addressed again before then.
    deaf_s: float = 0.0
    # The drive needs this long after the exchange before it is addressed again (a family's
    # pacing: Yaskawa after a parameter write); the other drives are served meanwhile.
    settle_s: float = 0.0

    @property
    def expects_reply(self) -> bool:
        """Whether a reply will come (not for broadcasts and resets)."""
        return self.reply_length > 0


@dataclass(slots=True, frozen=True, kw_only=True)
class DriveStatus:
    """A drive's status word in vendor-neutral terms, with the raw word kept."""

    word: int
    running: bool
    fault: bool
    warning: bool
    at_reference: bool
    reverse: bool | None = None  # None: this reply does not tell the direction
    accepts_bus_control: bool = True  # False: in local operation, bus commands are ignored


@dataclass(slots=True, frozen=True)
class Condition:
    """One active alarm or warning: the vendor's number and its text."""

    code: int
    text: str


@dataclass(slots=True, frozen=True, kw_only=True)
class ConditionReport:
    """The complete set of active alarms or warnings from one source word.

    A drive can spread its conditions over several words (FC: 16-90 and 16-91); each
    report replaces what earlier reports from the same ``source`` said.
    """

    kind: str  # "alarm" or "warning"
    source: str
    active: tuple[Condition, ...]


@dataclass(slots=True, frozen=True, kw_only=True)
class ParameterValue:
    """A parameter value read from (or confirmed by) a drive."""

    parameter: ParameterKey
    index: int
    raw: int | None  # None for text
    value: float | str
    unit: str
    # The manual's name ("Motor Current"), "" when the codec's table lacks the parameter.
    # It follows from ``parameter``, so it takes no part in equality.
    title: str = field(default="", compare=False)


@dataclass(slots=True, frozen=True)
class DriveError:
    """A drive's refusal: its error code and the code's text."""

    code: int
    text: str


@dataclass(slots=True, frozen=True, kw_only=True)
class Reply:
    """What one reply told the master, in vendor-neutral terms."""

    address: int
    status: DriveStatus | None = None
    # The output frequency, negative while the reply says the motor turns in reverse (FC);
    # protocols that report percent of nominal convert with the drive's nominal frequency.
    output_frequency_hz: float | None = None
    # Whether that frequency is a signed reading whose sign is the direction (a signed
    # Modbus register); False for a magnitude, which says nothing of the direction. FC
    # puts its sign into ``status.reverse`` itself.
    output_frequency_signed: bool = False
    value: ParameterValue | None = None
    conditions: ConditionReport | None = None
    error: DriveError | None = None  # the drive refused the request


class DriveCodec(Protocol):
    """Builds a vendor's exchanges and reads its replies. Pure: no I/O, no clock."""

    protocol: str
    addresses: range  # the drive addresses this protocol (and address format) can reach
    can_broadcast: bool  # whether control(0, …) reaches every drive at once

    def new_framer(self) -> Framer:
        """A framer for the replies of this protocol."""

    def min_pause_s(self, char_s: float) -> float:
        """The pause the protocol asks after a reply before the next request."""

    def parameter(self, text: str) -> ParameterKey:
        """The key of a parameter written the manual's way; UsageError if it is not one."""

    def default_monitor(self) -> tuple[ParameterKey, ...]:
        """Parameters worth watching when the config names none."""

    def poll_sequence(self, monitor: tuple[ParameterKey, ...]) -> tuple[ParameterKey | None, ...]:
        """What successive idle polls of a drive read, in rotation (None: status only)."""

    def condition_parameters(self, *, alarms: bool, warnings: bool) -> tuple[ParameterKey, ...]:
        """Parameters to read at once when the status shows alarms or warnings changed."""

    def poll(
        self, address: int, intent: ControlIntent | None, read: ParameterKey | None
    ) -> Exchange:
        """The idle poll of one drive, reading ``read`` besides the status.

        ``intent`` is the commanded state to keep feeding (None: monitor only — the drive
        must not be commanded by this request).
        """

    def control(self, address: int, intent: ControlIntent) -> tuple[Exchange, ...]:
        """The exchanges that command ``intent`` (address 0 broadcasts)."""

    def read(
        self, address: int, parameter: ParameterKey, index: int, intent: ControlIntent | None
    ) -> tuple[Exchange, ...]:
        """The exchanges that read a parameter, in order; the last one's reply holds the value.

        ``intent`` rides along where the protocol carries it. Most protocols need one
        exchange; some must select something first (Mitsubishi: the parameter page, HFF).
        """

    def write(
        self,
        address: int,
        parameter: ParameterKey,
        index: int,
        value: float | str,
        intent: ControlIntent | None,
        *,
        persist: bool = False,
    ) -> tuple[Exchange, ...]:
        """The exchanges that write a parameter, in order; the last one's reply confirms it.

        UsageError if the value cannot be represented. ``persist`` also stores it in
        non-volatile memory where the protocol tells the two apart (FC: AK E/D instead of
        2/3).
        """

    def parse(self, exchange: Exchange, frame: bytes) -> Reply:
        """The reply to ``exchange``; ProtocolError if ``frame`` does not answer it."""
