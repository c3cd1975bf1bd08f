"""Parameters through the page, and values in their setting unit (§9)."""

from __future__ import annotations

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from fcmaster.errors import UsageError
from fcmaster.protocol.codec import ParameterKey
from fcmaster.protocol.mitsubishi import PARAMETERS, lookup, parse_parameter, resolve
from fcmaster.protocol.mitsubishi.parameters import SETTING_8888, SETTING_9999, ParameterSpec


@pytest.mark.parametrize(
    ("number", "page", "read", "write"),
    [(7, 0, 0x07, 0x87), (122, 1, 0x16, 0x96), (549, 5, 0x31, 0xB1), (899, 8, 0x63, 0xE3)],
)
def test_page_and_codes(number: int, page: int, read: int, write: int) -> None:
    # §9: read code = number mod 100, write = 0x80 + that, page = number div 100.
    spec = lookup(number)
    assert (spec.page, spec.read_code, spec.write_code) == (page, read, write)


def test_special_settings_travel_as_ffff_and_fffe() -> None:
    spec = lookup(122)
    assert (spec.to_raw(9999), spec.to_raw(8888)) == (0xFFFF, 0xFFFE)
    assert (spec.to_value(0xFFFF), spec.to_value(0xFFFE)) == (9999.0, 8888.0)
    assert spec.to_raw(999.8) == 9998


@pytest.mark.parametrize("value", [-1.0, 0x1000000, float("nan"), float("inf")])
def test_values_that_cannot_travel_are_refused(value: float) -> None:
    with pytest.raises(UsageError):
        lookup(7).to_raw(value)


@given(st.sampled_from(sorted(PARAMETERS)), st.integers(0, 0xFFFFFF))
def test_values_round_trip(number: int, raw: int) -> None:
    spec = PARAMETERS[number]
    value = spec.to_value(raw)
    # A value that reads as 9999 or 8888 is written as the special setting (HFFFF/HFFFE), by
    # design; for a parameter counted in whole units that includes raw 9999 and 8888 data.
    assume(value not in (9999.0, 8888.0) or raw in (SETTING_9999, SETTING_8888))
    assert spec.to_raw(value) == raw


def test_a_whole_unit_parameter_writes_9999_and_8888_as_the_special_settings() -> None:
    spec = PARAMETERS[77]
    assert (spec.to_raw(spec.to_value(9999)), spec.to_raw(spec.to_value(8888))) == (
        0xFFFF,
        0xFFFE,
    )


def test_parameters_outside_the_table_are_raw() -> None:
    assert lookup(500) == ParameterSpec(number=500)


def test_foreign_keys_are_refused() -> None:
    with pytest.raises(UsageError):
        resolve(ParameterKey("16-13", 1613))
    with pytest.raises(UsageError):
        resolve(ParameterKey("H7A", 0x7A))
    assert resolve(parse_parameter("H7A")).name == "inverter status monitor"
