"""Alarm, warning and extended status words (16-90 … 16-94; protocols/danfoss-fc.md §9).

Each word is a 32-bit read-only parameter in which a set bit means active. Decoding gives
``(code, text)`` pairs: ``code`` is the drive's own alarm or warning number (A13 → 13) where
the manual gives one. A bit the manual names without a number, or a bit of a word whose
layout is product-specific (16-91, 16-93), gets a code above 900 — ``900 + 32 × word + bit``
with word 0 for the first word and 1 for the second — so codes never collide with the
drive's own numbers and stay stable. The raw words are always kept beside the decode.

The names are the FC 301/302 layout; FC 102/202 share the lower bits.
"""

from __future__ import annotations

from typing import Final

UNNUMBERED_BASE: Final = 900

# bit → (alarm number or None, text)
ALARM_WORD: Final[dict[int, tuple[int | None, str]]] = {
    0: (28, "Brake check"),
    1: (69, "Power card over-temperature"),
    2: (14, "Earth fault"),
    3: (65, "Control card over-temperature"),
    4: (17, "Control word timeout"),
    5: (13, "Over current"),
    6: (12, "Torque limit"),
    7: (11, "Motor thermistor over-temperature"),
    8: (10, "Motor ETR over-temperature"),
    9: (9, "Inverter overloaded"),
    10: (8, "DC under-voltage"),
    11: (7, "DC over-voltage"),
    12: (16, "Short circuit"),
    13: (33, "Inrush fault"),
    14: (4, "Mains phase loss"),
    15: (None, "AMA not OK"),
    16: (2, "Live zero error"),
    17: (38, "Internal fault"),
    18: (26, "Brake overload"),
    19: (30, "Motor phase U missing"),
    20: (31, "Motor phase V missing"),
    21: (32, "Motor phase W missing"),
    22: (34, "Fieldbus fault"),
    23: (47, "24 V supply low"),
    24: (36, "Mains failure"),
    25: (48, "1.8 V supply low"),
    26: (25, "Brake resistor short circuit"),
    27: (27, "Brake IGBT"),
    28: (67, "Option change"),
    29: (80, "Drive initialised"),
    30: (68, "Safe stop"),
    31: (63, "Mechanical brake low"),
}

WARNING_WORD: Final[dict[int, tuple[int | None, str]]] = {
    0: (28, "Brake check"),
    1: (69, "Power card over-temperature"),
    2: (14, "Earth fault"),
    3: (65, "Control card over-temperature"),
    4: (17, "Control word timeout"),
    5: (13, "Over current"),
    6: (12, "Torque limit"),
    7: (11, "Motor thermistor over-temperature"),
    8: (10, "Motor ETR over-temperature"),
    9: (9, "Inverter overloaded"),
    10: (8, "DC under-voltage"),
    11: (7, "DC over-voltage"),
    12: (6, "DC voltage low"),
    13: (5, "DC voltage high"),
    14: (4, "Mains phase loss"),
    15: (3, "No motor"),
    16: (2, "Live zero error"),
    17: (1, "10 V low"),
    18: (26, "Brake overload"),
    19: (25, "Brake resistor"),
    20: (27, "Brake IGBT"),
    21: (49, "Speed limit"),
    22: (34, "Fieldbus fault"),
    23: (47, "24 V supply low"),
    24: (36, "Mains failure"),
    25: (59, "Current limit"),
    26: (66, "Low temperature"),
    27: (64, "Voltage limit"),
    28: (90, "Encoder loss"),
    29: (62, "Output frequency limit"),
    30: (68, "Safe stop"),
    31: (None, "Extended status word active"),
}

EXT_STATUS_WORD: Final[dict[int, str]] = {
    0: "Ramping",
    1: "AMA running",
    2: "Start CW/CCW",
    3: "Slow down",
    4: "Catch up",
    5: "Feedback high",
    6: "Feedback low",
    7: "Output current high",
    8: "Output current low",
    9: "Output frequency high",
    10: "Output frequency low",
    11: "Brake check OK",
    12: "Braking max",
    13: "Braking",
    14: "Out of speed range",
    15: "Over-voltage control active",
    16: "AC brake",
    17: "Password time lock",
    18: "Password protection",
    19: "Reference high",
    20: "Reference low",
    21: "Local/remote reference",
}


def decode_alarm_word(word: int) -> list[tuple[int, str]]:
    """Active alarms of 16-90 as ``(alarm number, text)``."""
    return _decode(word, ALARM_WORD, word_index=0)


def decode_warning_word(word: int) -> list[tuple[int, str]]:
    """Active warnings of 16-92 as ``(warning number, text)``."""
    return _decode(word, WARNING_WORD, word_index=0)


def decode_alarm_word_2(word: int) -> list[tuple[int, str]]:
    """Active bits of 16-91, whose layout is product-specific, as numbered entries."""
    return _decode(word, {}, word_index=1, label="Alarm word 2")


def decode_warning_word_2(word: int) -> list[tuple[int, str]]:
    """Active bits of 16-93, whose layout is product-specific, as numbered entries."""
    return _decode(word, {}, word_index=1, label="Warning word 2")


def decode_ext_status_word(word: int) -> list[tuple[int, str]]:
    """Active bits of 16-94 as ``(bit, text)``."""
    return [
        (bit, EXT_STATUS_WORD.get(bit, f"Extended status bit {bit}"))
        for bit in range(32)
        if word >> bit & 1
    ]


def _decode(
    word: int,
    table: dict[int, tuple[int | None, str]],
    *,
    word_index: int,
    label: str = "",
) -> list[tuple[int, str]]:
    active = []
    for bit in range(32):
        if word >> bit & 1:
            number, text = table.get(bit, (None, f"{label} bit {bit}"))
            code = UNNUMBERED_BASE + 32 * word_index + bit if number is None else number
            active.append((code, text))
    return active
