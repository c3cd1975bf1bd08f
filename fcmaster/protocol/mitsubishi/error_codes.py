"""Error codes after NAK (§5) and fault codes of the fault history H74-H77 (§11).

Fault codes are the typical 700-series data codes (protocols/mitsubishi.md §11, [M?]);
models add their own, so a code not listed is shown raw (``0x..``) and never guessed.
"""

from __future__ import annotations

from typing import Final

# §5. Codes 0-5 count toward the E.PUE/E.SER trip (Pr.121); 7 and A-C do not.
ERROR_CODES: Final[dict[int, str]] = {
    0x0: "Computer NAK error: more consecutive errors than the retry count allows",
    0x1: "Parity error",
    0x2: "Sum check error",
    0x3: "Protocol error: syntax, timing, or CR/LF not as set (Pr.124)",
    0x4: "Framing error: stop bits not as set",
    0x5: "Overrun error: new data before the previous request was received",
    0x7: "Character error: a character other than 0-9, A-F or a control code",
    0xA: "Mode error: not in network operation, link not the command source, or running",
    0xB: "Instruction code error: the instruction code does not exist",
    0xC: "Data range error: invalid data for this write",
    0xF: "No error",
}

MODE_ERROR: Final = 0xA
INSTRUCTION_CODE_ERROR: Final = 0xB
DATA_RANGE_ERROR: Final = 0xC
COUNTS_TOWARD_TRIP: Final = frozenset(range(6))

# §11: data of H74-H77, two codes per word.
FAULT_CODES: Final[dict[int, tuple[str, str]]] = {
    0x10: ("E.OC1", "overcurrent trip during acceleration"),
    0x11: ("E.OC2", "overcurrent trip at constant speed"),
    0x12: ("E.OC3", "overcurrent trip during deceleration or stop"),
    0x20: ("E.OV1", "regenerative overvoltage during acceleration"),
    0x21: ("E.OV2", "regenerative overvoltage at constant speed"),
    0x22: ("E.OV3", "regenerative overvoltage during deceleration or stop"),
    0x30: ("E.THT", "inverter overload (transistor thermal)"),
    0x31: ("E.THM", "motor overload (electronic thermal relay)"),
    0x40: ("E.FIN", "heatsink overheat"),
    0x50: ("E.IPF", "instantaneous power failure"),
    0x51: ("E.UVT", "undervoltage"),
    0x52: ("E.ILF", "input phase loss"),
    0x60: ("E.OLT", "stall prevention stop"),
    0x70: ("E.BE", "brake transistor alarm"),
    0x80: ("E.GF", "output-side ground fault overcurrent"),
    0x81: ("E.LF", "output phase loss"),
    0x90: ("E.OHT", "external thermal relay"),
    0x91: ("E.PTC", "PTC thermistor"),
    0xA0: ("E.OPT", "option fault"),
    0xA1: ("E.OP1", "communication option fault"),
    0xB0: ("E.PE", "parameter storage device fault"),
    0xB1: ("E.PUE", "PU disconnection, or PU-port communication errors or signal loss"),
    0xB2: ("E.RET", "retry count excess"),
    0xB3: ("E.PE2", "parameter storage device fault (main circuit board)"),
    0xC0: ("E.CPU", "CPU fault"),
    0xC1: ("E.CTE", "operation panel / RS-485 terminal power supply short circuit"),
    0xC2: ("E.P24", "24 V DC output short circuit"),
    0xC4: ("E.CDO", "output current detection value exceeded"),
    0xC5: ("E.IOH", "inrush current limit circuit fault"),
    0xC6: ("E.SER", "communication fault on the RS-485 terminals"),
    0xC7: ("E.AIE", "analog input fault"),
    0xC8: ("E.USB", "USB communication fault"),
    0xF1: ("E.1", "option fault (slot 1)"),
    0xF2: ("E.2", "option fault (slot 2)"),
    0xF3: ("E.3", "option fault (slot 3)"),
    0xF6: ("E.6", "CPU fault"),
    0xF7: ("E.7", "CPU fault"),
}

NO_FAULT: Final = 0x00


def error_text(code: int) -> str:
    """Text of a NAK error code; unused codes get a generic one."""
    return ERROR_CODES.get(code, f"Error code H{code:X} (not used)")


def fault_text(code: int) -> str:
    """``"E.OC1 overcurrent trip during acceleration"``, or ``"0x.."`` for an unknown code."""
    known = FAULT_CODES.get(code)
    if known is None:
        return "no fault" if code == NO_FAULT else f"0x{code:02X}"
    return f"{known[0]} {known[1]}"


def fault_pair(word: int) -> tuple[int, int]:
    """The two fault codes of an H74-H77 word: (newer, older) = (bits 7-0, bits 15-8)."""
    return word & 0xFF, (word >> 8) & 0xFF
