"""The simulated ENC drive's function codes: ranges, factory settings and the store.

Units and names come from the codec's table (:data:`fcmaster.protocol.enc.FUNCTION_CODES`),
so the simulator and the master scale values alike. This module adds what only a drive
knows: each code's range or options, its factory setting, and whether it may change while
the motor turns. Values are kept raw (the 16-bit integers on the wire).

Where the figures come from:

* F2.14-F2.17 and F2.53: ranges and factory settings as protocols/enc.md §1 gives them;
  the manual marks all five as changeable only while stopped.
* F0.00-F0.03, F0.08 and F0.09: our sources give no ranges, so these are the simulator's
  own choices, kept plausible: F0.00 and F0.02 default to 3 (serial port), so a simulated
  drive obeys the bus unless it is set up otherwise; ramps default to 5.0 s.
* The upper-limit frequency bounds F0.01 and every frequency the bus sends (§4.2:
  "0 Hz … upper-limit frequency"). Its own function code is not in our sources, so it is
  a setting of the simulated drive (``DriveSettings.max_frequency_hz``), not a code the
  bus can reach.
* F2.53 = 1-4 switches to binary frames, which nobody has described (§1): the simulator
  speaks only the ASCII frames and refuses those values.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

from fcmaster.errors import FcmasterError, UsageError
from fcmaster.protocol.enc.codes import ResponseCode
from fcmaster.protocol.enc.frame import Command
from fcmaster.protocol.enc.parameters import (
    FUNCTION_CODES,
    ValueSpec,
    format_parameter,
    make_code,
    parse_parameter,
    split_code,
)

SERIAL_CHANNEL: Final = 3  # F0.00 / F0.02 option "serial port" (§1)
BAUD_OPTIONS: Final = (1200, 2400, 4800, 9600, 19200, 38400)  # F2.14 units digit (§1)
PARITY_OPTIONS: Final = {"N": 0, "E": 1, "O": 2}  # F2.14 tens digit, 1 stop bit (§1)

FREQUENCY_CHANNEL: Final = 0x0000  # F0.00
DIGITAL_FREQUENCY: Final = 0x0001  # F0.01
RUN_CHANNEL: Final = 0x0002  # F0.02
DIRECTION: Final = 0x0003  # F0.03
ACCELERATION: Final = 0x0008  # F0.08
DECELERATION: Final = 0x0009  # F0.09
COMMUNICATION: Final = 0x020E  # F2.14
LOCAL_ADDRESS: Final = 0x020F  # F2.15
TIMEOUT: Final = 0x0210  # F2.16
RESPONSE_DELAY: Final = 0x0211  # F2.17
FRAME_FORMAT: Final = 0x0235  # F2.53


class Refused(FcmasterError):
    """A request the drive answers with a response code other than 00 (§5)."""

    def __init__(self, code: int, message: str) -> None:
        self.code = code
        super().__init__(message)


def refused(message: str) -> Refused:
    """Response 30: not allowed now, not accepted, out of range (§5)."""
    return Refused(ResponseCode.REFUSED, message)


def frame_error(message: str) -> Refused:
    """Response 20: a field out of range, a wrong length or a wrong checksum (§5)."""
    return Refused(ResponseCode.FRAME_ERROR, message)


@dataclass(slots=True, frozen=True, kw_only=True)
class Setting:
    """A function code as the drive sees it (raw values)."""

    default: int
    low: int = 0
    high: int = 0xFFFF
    options: frozenset[int] | None = None  # an option list instead of a range
    stopped_only: bool = False  # refused with response 30 while the motor turns


_COMMUNICATION_OPTIONS: Final = frozenset(
    tens * 10 + units for tens in range(len(PARITY_OPTIONS)) for units in range(len(BAUD_OPTIONS))
)

SETTINGS: Final[dict[int, Setting]] = {
    FREQUENCY_CHANNEL: Setting(default=SERIAL_CHANNEL, high=6),
    DIGITAL_FREQUENCY: Setting(default=5000),  # 50.00 Hz, bounded by the upper limit
    RUN_CHANNEL: Setting(default=SERIAL_CHANNEL, high=3),
    DIRECTION: Setting(default=0, high=1),
    ACCELERATION: Setting(default=50, low=1, high=36000),  # 5.0 s
    DECELERATION: Setting(default=50, low=1, high=36000),
    COMMUNICATION: Setting(default=3, options=_COMMUNICATION_OPTIONS, stopped_only=True),
    LOCAL_ADDRESS: Setting(default=1, high=127, stopped_only=True),
    TIMEOUT: Setting(default=0, high=10000, stopped_only=True),  # 0.1 s; 0 = off
    RESPONSE_DELAY: Setting(default=5, high=200, stopped_only=True),  # ms
    FRAME_FORMAT: Setting(default=0, options=frozenset({0}), stopped_only=True),
}


def spec(index: int) -> ValueSpec:
    """Name, unit and scaling of function code ``index``, from the codec's table."""
    return FUNCTION_CODES[index]


def name(index: int) -> str:
    """``F2.16`` for 0x0210."""
    return format_parameter(make_code(Command.READ_PARAMETER, index))


class ParameterStore:
    """The raw values of one drive's function codes."""

    def __init__(
        self, overrides: Mapping[int, int] | None = None, *, upper_limit_hz: float
    ) -> None:
        """Factory settings, then ``overrides`` (index → raw), each checked like a bus write."""
        self.upper_limit_hz = upper_limit_hz
        self._values = {index: setting.default for index, setting in SETTINGS.items()}
        self._values[DIGITAL_FREQUENCY] = min(self._values[DIGITAL_FREQUENCY], self.upper_raw)
        for index, raw in (overrides or {}).items():
            if index not in SETTINGS:
                raise UsageError(f"function code {name(index)} cannot be set")
            try:
                self.set(index, raw, running=False)
            except Refused as exc:
                raise UsageError(f"function code {name(index)} = {raw}: {exc}") from None

    def __getitem__(self, index: int) -> int:
        return self._values[index]

    def value(self, index: int) -> float:
        """The value of ``index`` in its unit (F0.08 raw 50 → 5.0 s)."""
        return spec(index).to_value(self._values[index])

    @property
    def upper_raw(self) -> int:
        """The upper-limit frequency in 0.01 Hz."""
        return round(self.upper_limit_hz * 100)

    def set(self, index: int, raw: int, *, running: bool) -> None:
        """Store ``raw``, or raise :class:`Refused` (30) as the drive would."""
        setting = SETTINGS[index]
        if setting.stopped_only and running:
            raise refused(f"{name(index)} can only change while the motor is stopped")
        if setting.options is not None:
            if raw not in setting.options:
                raise refused(f"{name(index)} has no option {raw}")
        else:
            high = min(setting.high, self.upper_raw) if index == DIGITAL_FREQUENCY else setting.high
            if not setting.low <= raw <= high:
                raise refused(f"{name(index)}: {raw} is outside {setting.low}-{high}")
        self._values[index] = raw


def overrides_from_values(values: Mapping[str, float]) -> dict[int, int]:
    """``{"F0.08": 1.0}`` (the function code's unit) → ``{0x0008: 10}`` raw."""
    out = {}
    for text, value in values.items():
        command, index = split_code(parse_parameter(text).code)
        if command != Command.READ_PARAMETER or index not in SETTINGS:
            raise UsageError(f"parameter {text} cannot be set on a simulated ENC drive")
        out[index] = spec(index).to_raw(value)
    return out
