"""16-90 / 16-92 / 16-94 and the product-specific 16-91 / 16-93 (protocols/danfoss-fc.md §9).

The per-bit numbers below are transcribed from the table in §9 (FC 301/302 layout), one
column at a time, bit 0 first. ``None`` marks a bit the table names without a number.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.protocol.danfoss_fc import (
    decode_alarm_word,
    decode_alarm_word_2,
    decode_ext_status_word,
    decode_warning_word,
    decode_warning_word_2,
)

# fmt: off
ALARM_NUMBERS = [
    28, 69, 14, 65, 17, 13, 12, 11,  # bits 0-7
    10, 9, 8, 7, 16, 33, 4, None,  # bits 8-15 (15: AMA not OK)
    2, 38, 26, 30, 31, 32, 34, 47,  # bits 16-23
    36, 48, 25, 27, 67, 80, 68, 63,  # bits 24-31
]
WARNING_NUMBERS = [
    28, 69, 14, 65, 17, 13, 12, 11,  # bits 0-7
    10, 9, 8, 7, 6, 5, 4, 3,  # bits 8-15
    2, 1, 26, 25, 27, 49, 34, 47,  # bits 16-23
    36, 59, 66, 64, 90, 62, 68, None,  # bits 24-31 (31: extended status word active)
]
# fmt: on
UNNUMBERED = 900  # the module's documented stand-in: 900 + 32 × word + bit

Decoder = Callable[[int], list[tuple[int, str]]]


@pytest.mark.parametrize("bit", range(32), ids=lambda bit: f"bit-{bit}")
def test_alarm_word_bit_gives_the_alarm_number(bit: int) -> None:
    [(code, text)] = decode_alarm_word(1 << bit)
    number = ALARM_NUMBERS[bit]
    assert code == (UNNUMBERED + bit if number is None else number)
    assert text


@pytest.mark.parametrize("bit", range(32), ids=lambda bit: f"bit-{bit}")
def test_warning_word_bit_gives_the_warning_number(bit: int) -> None:
    [(code, text)] = decode_warning_word(1 << bit)
    number = WARNING_NUMBERS[bit]
    assert code == (UNNUMBERED + bit if number is None else number)
    assert text


@pytest.mark.parametrize(
    ("decode", "word", "expected"),
    [
        pytest.param(decode_alarm_word, 0x0000_0010, [(17, "Control word timeout")], id="A17"),
        pytest.param(decode_alarm_word, 0x0000_0020, [(13, "Over current")], id="A13"),
        pytest.param(decode_alarm_word, 0x0000_4000, [(4, "Mains phase loss")], id="A4"),
        pytest.param(decode_alarm_word, 0x0000_8000, [(915, "AMA not OK")], id="AMA-not-OK"),
        pytest.param(
            decode_alarm_word, 0x0000_0A00, [(9, "Inverter overloaded"), (7, "DC over-voltage")],
            id="A9-and-A7-in-bit-order",
        ),
        pytest.param(decode_warning_word, 0x0000_1000, [(6, "DC voltage low")], id="W6"),
        pytest.param(decode_warning_word, 0x0000_8000, [(3, "No motor")], id="W3"),
        pytest.param(decode_warning_word, 0x0002_0000, [(1, "10 V low")], id="W1"),
        pytest.param(
            decode_warning_word, 0x8000_0000, [(931, "Extended status word active")],
            id="extended-status-active",
        ),
        pytest.param(decode_ext_status_word, 0x0000_0001, [(0, "Ramping")], id="ramping"),
        pytest.param(decode_ext_status_word, 0x0000_2000, [(13, "Braking")], id="braking"),
        pytest.param(decode_alarm_word, 0, [], id="no-alarm"),
    ],
)  # fmt: skip
def test_words_by_hand(decode: Decoder, word: int, expected: list[tuple[int, str]]) -> None:
    assert decode(word) == expected


def test_ext_status_reserved_bits_still_come_out() -> None:
    [(bit, text)] = decode_ext_status_word(1 << 22)
    assert bit == 22
    assert "22" in text


@pytest.mark.parametrize(
    ("decode", "bit", "code"),
    [
        (decode_alarm_word_2, 0, 932),
        (decode_alarm_word_2, 31, 963),
        (decode_warning_word_2, 5, 937),
    ],
)
def test_product_specific_words_get_stable_codes_above_the_first_words(
    decode: Decoder, bit: int, code: int
) -> None:
    [(got, text)] = decode(1 << bit)
    assert got == code
    assert str(bit) in text


def test_numbered_codes_never_collide_with_stand_ins() -> None:
    numbers = {n for n in ALARM_NUMBERS + WARNING_NUMBERS if n is not None}
    assert max(numbers) < UNNUMBERED


DECODERS: list[Decoder] = [
    decode_alarm_word,
    decode_warning_word,
    decode_alarm_word_2,
    decode_warning_word_2,
    decode_ext_status_word,
]


@given(st.integers(0, 0xFFFF_FFFF), st.sampled_from(DECODERS))
def test_one_entry_per_set_bit_in_bit_order(word: int, decode: Decoder) -> None:
    entries = decode(word)
    assert len(entries) == bin(word).count("1")
    singles = [decode(1 << bit)[0] for bit in range(32) if word >> bit & 1]
    assert entries == singles
