"""What the master reads and writes, named the manual's way (§4.1, §4.3).

Names :func:`parse_parameter` accepts (case-insensitive, surrounding blanks ignored):

* ``"F0.01"`` — a function code: group ``F0``-``F9``, ``FA``-``FF`` (FD is 0D, FF is 0F)
  and number 0-255 in decimal. Read with command 13, written with command 14; the index
  is group (high byte) and number (low byte): F2.11 → ``020B`` (§4.3).
* ``"11/0001"`` — a running value: command 11 and its four-hex-digit index (§4.1), or one
  of the readable names in :data:`VALUE_ALIASES` (``"running_frequency"`` …).
* ``"10/0000"`` (``"slave_state"``) — command 10: its value is the response code (§5);
  ``"15/0000"`` (``"software_version"``) — command 15.
* ``"13/0001"`` and ``"14/0001"`` — the same function code as ``"F0.01"``.

The state word (11/000F, §6) is read by :func:`decode_status`; it has no fault bit and no
at-reference bit: the fault comes in every reply's failure index, and the protocol does not
say whether the drive has reached its set frequency, so ``at_reference`` is False.

A :class:`~fcmaster.protocol.codec.ParameterKey` carries the command in bits 16-23 and the
index in bits 0-15 of its ``code``; its ``name`` is the canonical spelling (``"F0.01"``,
``"11/0001"``, ``"10/0000"``, ``"15/0000"``). Command 12 is run control, not a parameter.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass
from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.codec import DriveStatus, ParameterKey
from fcmaster.protocol.enc.codes import NO_FAULT
from fcmaster.protocol.enc.frame import Command

_FUNCTION_CODE = re.compile(r"^F([0-9A-F])\.(\d{1,3})$")
_COMMAND_INDEX = re.compile(r"^(\d{2})/([0-9A-F]{4})$")
_READABLE = frozenset((Command.LOOK_UP_STATE, Command.READ_VALUE, Command.SOFTWARE_VERSION))


@dataclass(slots=True, frozen=True, kw_only=True)
class ValueSpec:
    """How a raw 16-bit value reads: its name, unit and power of ten."""

    name: str
    unit: str = ""
    exponent: int = 0  # value = raw × 10**exponent

    def to_value(self, raw: int) -> float:
        """Raw integer → value in ``unit``."""
        return raw / 10.0**-self.exponent if self.exponent < 0 else float(raw * 10**self.exponent)

    def to_raw(self, value: float) -> int:
        """Value in ``unit`` → raw integer, rounded to the resolution."""
        return round(value * 10.0**-self.exponent)


# §4.1 command 11, index → (readable alias, spec)
RUNNING_VALUES: Final[dict[int, tuple[str, ValueSpec]]] = {
    0x00: ("set_frequency", ValueSpec(name="Current set frequency", unit="Hz", exponent=-2)),
    0x01: ("running_frequency", ValueSpec(name="Running frequency", unit="Hz", exponent=-2)),
    0x02: ("output_voltage", ValueSpec(name="Output voltage", unit="V")),
    0x03: ("output_current", ValueSpec(name="Output current", unit="A", exponent=-1)),
    0x04: ("dc_bus_voltage", ValueSpec(name="DC bus voltage", unit="V")),
    0x05: ("motor_speed", ValueSpec(name="Load (motor) speed", unit="rpm")),
    0x06: ("module_temperature", ValueSpec(name="Module temperature", unit="°C")),
    0x07: ("running_time", ValueSpec(name="Running time", unit="h")),
    0x08: ("accumulated_running_time", ValueSpec(name="Accumulated running time", unit="h")),
    0x09: ("input_terminals", ValueSpec(name="Input terminal state")),
    0x0A: ("output_terminals", ValueSpec(name="Output terminal state")),
    0x0B: ("vci", ValueSpec(name="Analog input VCI", unit="V", exponent=-2)),
    0x0C: ("cci", ValueSpec(name="Analog input CCI", unit="V", exponent=-2)),
    0x0D: ("reserved_0d", ValueSpec(name="Reserved", unit="V", exponent=-2)),
    # The table's unit; §4.1 and §10 question 6 say it deserves a check on a drive.
    0x0E: ("pulse_input", ValueSpec(name="External pulse input", unit="Hz", exponent=-2)),
    0x0F: ("state_word", ValueSpec(name="Inverter running state word")),
}
VALUE_ALIASES: Final[dict[str, int]] = {
    alias: Command.READ_VALUE << 16 | index for index, (alias, _) in RUNNING_VALUES.items()
} | {
    "slave_state": Command.LOOK_UP_STATE << 16,
    "software_version": Command.SOFTWARE_VERSION << 16,
}

# Function codes a gateway commonly touches (§1, §4.3); others read as raw integers.
FUNCTION_CODES: Final[dict[int, ValueSpec]] = {
    0x0000: ValueSpec(name="Frequency input channel"),
    0x0001: ValueSpec(name="Run frequency digital setting", unit="Hz", exponent=-2),
    0x0002: ValueSpec(name="Run command channel"),
    0x0003: ValueSpec(name="Run direction setting"),
    0x0008: ValueSpec(name="Acceleration time 1", unit="s", exponent=-1),
    0x0009: ValueSpec(name="Deceleration time 1", unit="s", exponent=-1),
    0x020E: ValueSpec(name="Communication configuration"),
    0x020F: ValueSpec(name="Local address"),
    0x0210: ValueSpec(name="Communication timeout detection", unit="s", exponent=-1),
    0x0211: ValueSpec(name="Local response delay", unit="ms"),
    0x0235: ValueSpec(name="Frame format"),
}

STATE_SPEC: Final = ValueSpec(name="Slave state (response code)")
VERSION_SPEC: Final = ValueSpec(name="Software version")


def make_code(command: int, index: int) -> int:
    """A ParameterKey code: command in bits 16-23, index in bits 0-15."""
    return command << 16 | index


def split_code(code: int) -> tuple[int, int]:
    """``(command, index)`` of a ParameterKey code."""
    return code >> 16, code & 0xFFFF


def parse_parameter(text: str) -> ParameterKey:
    """The key of a parameter written one of the ways the module docstring lists."""
    cleaned = text.strip().upper()
    alias = VALUE_ALIASES.get(cleaned.lower())
    if alias is not None:
        return key(alias)
    match = _FUNCTION_CODE.match(cleaned)
    if match:
        number = int(match[2])
        if number > 0xFF:
            raise UsageError(f"function code {text.strip()}: the number must be 0-255")
        return key(make_code(Command.READ_PARAMETER, int(match[1], 16) << 8 | number))
    match = _COMMAND_INDEX.match(cleaned)
    if match:
        command, index = int(match[1]), int(match[2], 16)
        if command in (Command.READ_PARAMETER, Command.WRITE_PARAMETER):
            return key(make_code(Command.READ_PARAMETER, index))
        if command in _READABLE:
            if command != Command.READ_VALUE and index:
                raise UsageError(f"command {command} takes index 0000, not {match[2]}")
            return key(make_code(command, index))
        if command == Command.RUN_CONTROL:
            raise UsageError("command 12 is run control: use a control action, not a parameter")
        raise UsageError(f"{text.strip()!r}: command {command} is not one of 10-15")
    raise UsageError(
        f"parameter {text.strip()!r} is not written like F0.01, 11/0001 or running_frequency"
    )


def format_parameter(code: int) -> str:
    """The canonical name of a ParameterKey code."""
    command, index = split_code(code)
    if command == Command.READ_PARAMETER and index >> 8 <= 0xF:
        return f"F{index >> 8:X}.{index & 0xFF:02d}"
    return f"{command:02d}/{index:04X}"  # groups above FF have no F-notation


def key(code: int) -> ParameterKey:
    """The ParameterKey of a code, named canonically."""
    return ParameterKey(format_parameter(code), code)


def lookup(code: int) -> ValueSpec:
    """How the value of a ParameterKey code reads (a nameless raw spec when not tabled)."""
    command, index = split_code(code)
    if command == Command.READ_VALUE and index in RUNNING_VALUES:
        return RUNNING_VALUES[index][1]
    if command == Command.READ_PARAMETER:
        return FUNCTION_CODES.get(index, ValueSpec(name=""))
    if command == Command.LOOK_UP_STATE:
        return STATE_SPEC
    if command == Command.SOFTWARE_VERSION:
        return VERSION_SPEC
    return ValueSpec(name="")


RUNNING_FREQUENCY: Final = key(make_code(Command.READ_VALUE, 0x01))
STATE_WORD: Final = key(make_code(Command.READ_VALUE, 0x0F))


class StateWord(enum.IntFlag):
    """State-word bits, named by what a 1 means (§6)."""

    RUNNING = 1 << 0
    UNDERVOLTAGE = 1 << 1
    REVERSE = 1 << 2
    SWING_FREQUENCY = 1 << 3
    NORMAL_RUN = 1 << 4
    JOGGING = 1 << 5
    PLC_RUN = 1 << 6
    MULTI_STEP = 1 << 7
    PI_CLOSED_LOOP = 1 << 8
    SET_COUNT_REACHED = 1 << 9
    SPECIFIED_COUNT_REACHED = 1 << 10


def decode_status(word: int, fault_code: int) -> DriveStatus:
    """The vendor-neutral reading of a state word and the failure index beside it.

    Undervoltage (bit 1) is the one condition the word flags short of a trip, so it is the
    warning; a trip on undervoltage is fault 19.
    """
    return DriveStatus(
        word=word,
        running=bool(word & StateWord.RUNNING),
        fault=fault_code != NO_FAULT,
        warning=bool(word & StateWord.UNDERVOLTAGE),
        at_reference=False,
        reverse=bool(word & StateWord.REVERSE),
    )


# -- parameter sets (fcmaster.protocol.parameter_set) ------------------------------------

# A set is every function code of the table, in table order.
SET_MEMBERS: Final = tuple(
    (format_parameter(make_code(Command.READ_PARAMETER, index)), spec.name)
    for index, spec in FUNCTION_CODES.items()
)
IDENTITY: Final = (("15/0000", VERSION_SPEC.name),)
IDENTITY_MATCH: Final[frozenset[str]] = frozenset()  # a version number says nothing of fit
# The manual marks F2.14-F2.17 and F2.53 as changed only while stopped; it gives no marks
# for the F0 codes, so none is taken as changeable while running.
CHANGEABLE_WHILE_RUNNING: Final[frozenset[str]] = frozenset()
LINK_SETTINGS: Final = frozenset({"F2.14", "F2.15", "F2.53"})  # baud/format, address, frames
FREQUENCY_CEILINGS: Final[frozenset[str]] = frozenset()  # the table has no maximum frequency
SET_RANGES: Final[tuple[tuple[str, float, float], ...]] = ()  # none taken from the manuals yet
