"""Instruction codes that do not depend on the link-parameter page (protocols/mitsubishi.md §9).

Read codes are 00-7F and write codes are the read code + 0x80. Codes 00-63 (80-E3) address
parameters through the page set with HFF (see ``parameters``); the codes here (6C-7F and
their writes, and write-only commands) mean the same on every page. An item is named by
its read code where it has one (``H6D`` reads the RAM set frequency and, written, sends
HED) and by its write code otherwise (``HFA``).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.mitsubishi.error_codes import fault_pair, fault_text
from fcmaster.protocol.mitsubishi.profile import frequency_hz, frequency_raw


class Kind(enum.Enum):
    """How an item's data turns into a value."""

    NUMBER = "number"  # raw × step, in unit
    FREQUENCY = "frequency"  # 0.01 Hz
    STATUS = "status"  # H7A bits
    STATUS_EXTENDED = "status_extended"  # H79 bits
    FAULTS = "faults"  # two fault codes (§11)
    TEXT = "text"  # E3: 20 characters
    COMMAND = "command"  # run command, reset, clears: only through control() or not at all


@dataclass(slots=True, frozen=True, kw_only=True)
class Instruction:
    """One page-independent item: its codes, data width and meaning."""

    name: str
    read: int | None
    write: int | None
    digits: int  # data width of a write, and of a read reply
    kind: Kind = Kind.NUMBER
    step: float = 1.0
    unit: str = ""
    reply_digits: tuple[int, ...] = ()  # widths a read reply may have; () = (digits,)
    user_writable: bool = True  # False: reached through control(), or never

    @property
    def code(self) -> int:
        """The code the item is named by: its read code, or its write code."""
        code = self.read if self.read is not None else self.write
        assert code is not None  # every item has one or the other
        return code

    @property
    def key_name(self) -> str:
        """``H7A``: how the manuals and the user write the item."""
        return f"H{self.code:02X}"

    @property
    def read_widths(self) -> tuple[int, ...]:
        """Data widths a read reply may carry."""
        return self.reply_digits or (self.digits,)


def _i(
    name: str,
    read: int | None,
    write: int | None,
    digits: int,
    *,
    kind: Kind = Kind.NUMBER,
    step: float = 1.0,
    unit: str = "",
    reply_digits: tuple[int, ...] = (),
    user_writable: bool = True,
) -> Instruction:
    return Instruction(
        name=name,
        read=read,
        write=write,
        digits=digits,
        kind=kind,
        step=step,
        unit=unit,
        reply_digits=reply_digits,
        user_writable=user_writable,
    )


_F = Kind.FREQUENCY
INSTRUCTIONS: Final[tuple[Instruction, ...]] = (
    _i("second parameter changing", 0x6C, 0xEC, 2),
    _i("set frequency (RAM)", 0x6D, 0xED, 4, kind=_F, unit="Hz"),
    _i("set frequency (EEPROM)", 0x6E, 0xEE, 4, kind=_F, unit="Hz"),
    _i("output frequency", 0x6F, None, 4, kind=_F, unit="Hz"),
    _i("output current", 0x70, None, 4, step=0.01, unit="A"),
    _i("output voltage", 0x71, None, 4, step=0.1, unit="V"),
    _i("special monitor", 0x72, None, 4, reply_digits=(4, 6)),
    _i("special monitor selection", 0x73, 0xF3, 2),
    _i("fault history 1-2", 0x74, None, 4, kind=Kind.FAULTS),
    _i("fault history 3-4", 0x75, None, 4, kind=Kind.FAULTS),
    _i("fault history 5-6", 0x76, None, 4, kind=Kind.FAULTS),
    _i("fault history 7-8", 0x77, None, 4, kind=Kind.FAULTS),
    _i("inverter status monitor (extended)", 0x79, None, 4, kind=Kind.STATUS_EXTENDED),
    _i("inverter status monitor", 0x7A, None, 2, kind=Kind.STATUS),
    _i("operation mode", 0x7B, 0xFB, 4),
    _i("model name", 0x7C, None, 20, kind=Kind.TEXT),
    _i("link parameter expansion", 0x7F, 0xFF, 2),
    _i("multi command", None, 0xF0, 10, kind=Kind.COMMAND, user_writable=False),
    _i("fault history batch clear", None, 0xF4, 4, kind=Kind.COMMAND, user_writable=False),
    _i("run command (extended)", None, 0xF9, 4, kind=Kind.COMMAND, user_writable=False),
    _i("run command", None, 0xFA, 2, kind=Kind.COMMAND, user_writable=False),
    _i("parameter clear", None, 0xFC, 4, kind=Kind.COMMAND, user_writable=False),
    _i("inverter reset", None, 0xFD, 4, kind=Kind.COMMAND, user_writable=False),
)

BY_CODE: Final[dict[int, Instruction]] = {
    code: item for item in INSTRUCTIONS for code in (item.read, item.write) if code is not None
}

STATUS: Final = BY_CODE[0x7A]
STATUS_EXTENDED: Final = BY_CODE[0x79]
OUTPUT_FREQUENCY: Final = BY_CODE[0x6F]
SET_FREQUENCY_RAM: Final = BY_CODE[0x6D]
SET_FREQUENCY_EEPROM: Final = BY_CODE[0x6E]
FAULT_HISTORY: Final = BY_CODE[0x74]
LINK_PAGE: Final = BY_CODE[0x7F]
RUN_COMMAND: Final = BY_CODE[0xFA]
INVERTER_RESET: Final = BY_CODE[0xFD]

RESET_NO_REPLY: Final = 0x9696  # HFD data: reset at once, no reply (§2, §9)
RESET_AFTER_ACK: Final = 0x9966  # HFD data: ACK, then reset (E700/D700/F700PJ/800 only)

FIRST_PAGED_WRITE: Final = 0x80
LAST_PAGED_READ: Final = 0x63  # parameter codes 00-63 and 80-E3 follow the page (§9)


def is_paged(code: int) -> bool:
    """Whether ``code`` addresses a parameter through the link-parameter page."""
    return code <= LAST_PAGED_READ or FIRST_PAGED_WRITE <= code <= FIRST_PAGED_WRITE + 0x63


def request_widths(code: int) -> tuple[int, ...]:
    """Data widths a request with instruction ``code`` may carry (§6, §9).

    The one rule the codec's framer, the simulator's receiver and the simulated drive all
    cut requests by. A read code carries none. A write of two digits (A1: HEC, HF3, HFA,
    HFF) or of ten (the multi command HF0) carries just that; any other write, known or
    not, four or six (A or A2), which only the sum check tells apart.
    """
    if code < FIRST_PAGED_WRITE:  # read codes are 00-7F
        return (0,)
    item = BY_CODE.get(code)
    if item is not None and item.digits in (2, 10):
        return (item.digits,)
    return (4, 6)


def describe_code(code: int) -> str:
    """A short name for an instruction code, as in the manuals' tables."""
    item = BY_CODE.get(code)
    if item is not None:
        direction = "read" if code == item.read else "write"
        return f"{item.name} ({direction})"
    if is_paged(code):
        offset = code & 0x7F
        direction = "read" if code < FIRST_PAGED_WRITE else "write"
        return f"parameter {direction}: Pr.{offset}, Pr.1{offset:02d} … by the page (HFF)"
    return "unknown instruction code"


def item_value(item: Instruction, raw: int) -> float | str:
    """The value of ``raw`` data of ``item`` in its unit (fault texts for the history)."""
    if item.kind is Kind.FREQUENCY:
        return frequency_hz(raw)
    if item.kind is Kind.FAULTS:
        newer, older = fault_pair(raw)
        return f"{fault_text(newer)}; {fault_text(older)}"
    return round(raw * item.step, 6)


def item_raw(item: Instruction, value: float) -> int:
    """The data that writes ``value`` to ``item``; UsageError if its digits cannot carry it."""
    if item.kind is Kind.FREQUENCY:
        return frequency_raw(value)
    steps = value / item.step
    # Compared before rounding, so NaN and infinities are refused too.
    if not 0 <= steps < 16**item.digits - 0.5:
        raise UsageError(f"{item.key_name}: {value:g} does not fit in {item.digits} hex digits")
    return round(steps)
