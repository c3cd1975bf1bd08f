"""Numbers in two-character fields: addresses, response codes and fault codes (§3, §5, §7).

The manuals print commands in decimal (10-15) but the wire carries them in hexadecimal
("0A"-"0F"); every printed example proves it (§3). No source says whether the drive writes
its *own* numbers the same way, or as the digits the manual prints: addresses of 10 and
above (§10 question 2), the response codes (question 1) and the fault code in the failure
index (question 7). So each of them is a per-line :class:`NumberEncoding`:

* ``hex`` — the number in hexadecimal, like the commands: address 10 is "0A", response 20
  is "14", fault 16 is "10". The default everywhere: it is how every confirmed field works
  (§9: "encode every field as uppercase hex").
* ``decimal`` — the digits as printed: address 10 is "10", response 20 is "20". A field
  byte then holds binary-coded decimal, and only 0-99 can be written.

Decoding accepts both readings. Where both give a known meaning — only "14" for a
command-10 response (hex: 20 frame error; decimal: 14 ready, no control) and "10"-"17" in
the failure index — the line's encoding decides.
"""

from __future__ import annotations

import enum
from typing import Final

from fcmaster.errors import MalformedReply, UsageError
from fcmaster.protocol.codec import Condition, ConditionReport


class NumberEncoding(enum.StrEnum):
    """How a number is written into a two-character field."""

    HEX = "hex"
    DECIMAL = "decimal"


def number_encoding(value: str) -> NumberEncoding:
    """Parse a line option; UsageError names the choices."""
    try:
        return NumberEncoding(value)
    except ValueError:
        raise UsageError(f"{value!r} is not a number encoding (hex or decimal)") from None


def encode_number(value: int, encoding: NumberEncoding) -> int:
    """The field byte that writes ``value``: itself (hex) or its two BCD digits (decimal)."""
    if encoding is NumberEncoding.HEX:
        if not 0 <= value <= 0xFF:
            raise UsageError(f"{value} does not fit in two hex digits (0-255)")
        return value
    if not 0 <= value <= 99:
        raise UsageError(f"{value} does not fit in two decimal digits (0-99)")
    return (value // 10) << 4 | value % 10


def readings(field: int) -> dict[NumberEncoding, int]:
    """Every number a field byte can stand for: hex always, decimal when both nibbles are digits."""
    out = {NumberEncoding.HEX: field}
    high, low = field >> 4, field & 0xF
    if high <= 9 and low <= 9:
        out[NumberEncoding.DECIMAL] = high * 10 + low
    return out


def read_number(field: int, encoding: NumberEncoding, known: frozenset[int]) -> int | None:
    """The reading of ``field`` that is in ``known``, preferring ``encoding``; None if none is."""
    found = readings(field)
    preferred = found.get(encoding)
    if preferred is not None and preferred in known:
        return preferred
    for value in found.values():
        if value in known:
            return value
    return None


# ---------------------------------------------------------------- response codes (§5)


class ResponseCode(enum.IntEnum):
    """Response codes as the manual prints them."""

    NORMAL = 0  # commands 11-15: done; parameter change accepted; password right
    PARAMETER_NORMAL = 6  # tables 6 and 7 print it for commands 13 and 14 (§4.3, question 4)
    NOT_READY = 10  # command 10
    READY_11 = 11  # command 10: ready; control and frequency setting allowed
    READY_12 = 12  # command 10: the same as 11 by the manual (question 5)
    READY_NO_CONTROL_13 = 13  # command 10: ready; control not allowed
    READY_NO_CONTROL_14 = 14  # command 10: the same as 13 by the manual (question 5)
    FRAME_ERROR = 20  # any command: checksum, range, length or character error
    REFUSED = 30  # commands 11-15: not allowed now, value out of range, wrong password


RESPONSE_TEXTS: Final[dict[int, str]] = {
    0: "Normal",
    6: "Normal (parameter access)",
    10: "Not ready",
    11: "Ready; control and frequency setting allowed",
    12: "Ready; control and frequency setting allowed",
    13: "Ready; control and frequency setting not allowed",
    14: "Ready; control and frequency setting not allowed",
    20: "Frame error (checksum, command or index out of range, length, or a non-ASCII byte)",
    30: (
        "Refused (control not allowed now, parameter change not accepted, value out of "
        "range, or wrong password)"
    ),
}

STATE_CODES: Final = frozenset((10, 11, 12, 13, 14, 20))  # answers to command 10 (table 1)
_ACCESS_CODES: Final = frozenset((0, 20, 30))  # answers to commands 11-15 (table 2)
_PARAMETER_CODES: Final = _ACCESS_CODES | {6}  # 13 and 14 also "06" (tables 6, 7)
ANY_CODE: Final = STATE_CODES | _PARAMETER_CODES


def known_responses(command: int | None) -> frozenset[int]:
    """The response codes that can answer ``command`` (None: any command)."""
    if command is None:
        return ANY_CODE
    if command == 10:
        return STATE_CODES
    if command in (13, 14):
        return _PARAMETER_CODES
    return _ACCESS_CODES


def read_response(
    field: int, command: int | None, encoding: NumberEncoding, *, has_index: bool = True
) -> int:
    """The response code (as printed) in ``field``, answering ``command``.

    A reply without its index area can only be a frame error (§5), which settles the one
    collision ("14") whatever the line's encoding. MalformedReply if no reading is known.
    """
    known = known_responses(command)
    if not has_index and ResponseCode.FRAME_ERROR in readings(field).values():
        return ResponseCode.FRAME_ERROR
    code = read_number(field, encoding, known)
    if code is None:
        raise MalformedReply(
            f"response code {field:02X} is not one that answers "
            f"{'a command' if command is None else f'command {command}'}"
        )
    return code


def response_text(code: int) -> str:
    """Text of a response code as printed."""
    return RESPONSE_TEXTS.get(code, f"Response {code}")


# ---------------------------------------------------------------- fault codes (§7)

FAULT_TEXTS: Final[dict[int, str]] = {
    1: "Overcurrent during acceleration",
    2: "Overcurrent during deceleration",
    3: "Overcurrent at constant speed",
    4: "Overvoltage during acceleration",
    5: "Overvoltage during deceleration",
    6: "Overvoltage at constant speed",
    7: "Control power supply overvoltage",
    8: "Inverter overload",
    9: "Motor overload",
    10: "Inverter overheat",
    13: "Power module protection",
    14: "External equipment fault",
    15: "Current detection circuit fault",
    16: "RS-485 communication fault",
    19: "Undervoltage",
    20: "System disturbance",
    23: "EEPROM read/write error",
}
NO_FAULT: Final = 0
FAILURE_INDEX_SOURCE: Final = "failure_index"
MAX_FAULT: Final = 23  # codes 11, 12, 17, 18, 21 and 22 are reserved, but in range
_FAULT_RANGE: Final = frozenset(range(MAX_FAULT + 1))


def read_fault(field: int, encoding: NumberEncoding) -> int:
    """The fault code in a failure-index byte; 0 means no fault (§7, question 7).

    A byte no reading of which is a documented code is kept in the line's encoding (or hex
    when it has no decimal reading): a newer drive may know more faults than the manual.
    """
    code = read_number(field, encoding, _FAULT_RANGE)
    if code is not None:
        return code
    return readings(field).get(encoding, field)


def fault_text(code: int) -> str:
    """Text of a fault code; reserved and unknown codes get a generic one."""
    return FAULT_TEXTS.get(code, f"Fault {code}")


def fault_report(fault_code: int) -> ConditionReport:
    """The alarms a failure index reports: none for 0, else the one fault (§2: every reply)."""
    active = () if fault_code == NO_FAULT else (Condition(fault_code, fault_text(fault_code)),)
    return ConditionReport(kind="alarm", source=FAILURE_INDEX_SOURCE, active=active)
