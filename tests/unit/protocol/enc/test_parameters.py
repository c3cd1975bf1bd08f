"""Parameter names, value scaling and the running state word (§4.1, §4.3, §6)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.errors import UsageError
from fcmaster.protocol.codec import DriveStatus
from fcmaster.protocol.enc import (
    RUNNING_VALUES,
    StateWord,
    ValueSpec,
    decode_status,
    format_parameter,
    lookup,
    parse_parameter,
)


@pytest.mark.parametrize(
    ("text", "name", "code"),
    [
        ("F0.01", "F0.01", 0x0D_0001),
        ("f0.01", "F0.01", 0x0D_0001),
        (" F2.11 ", "F2.11", 0x0D_020B),  # §4.3: F2.11 → 020B
        ("F2.15", "F2.15", 0x0D_020F),
        ("FD.05", "FD.05", 0x0D_0D05),  # FD is group 0D
        ("FF.00", "FF.00", 0x0D_0F00),
        ("F0.5", "F0.05", 0x0D_0005),  # §4.3 erratum: F0.05 → 0005, not 000B
        ("F2.53", "F2.53", 0x0D_0235),
        ("13/0001", "F0.01", 0x0D_0001),
        ("14/020F", "F2.15", 0x0D_020F),
        ("13/1001", "13/1001", 0x0D_1001),  # group 10 has no F-notation
        ("11/0001", "11/0001", 0x0B_0001),
        ("11/000f", "11/000F", 0x0B_000F),
        ("running_frequency", "11/0001", 0x0B_0001),
        ("Output_Current", "11/0003", 0x0B_0003),
        ("state_word", "11/000F", 0x0B_000F),
        ("slave_state", "10/0000", 0x0A_0000),
        ("10/0000", "10/0000", 0x0A_0000),
        ("software_version", "15/0000", 0x0F_0000),
    ],
)
def test_parameter_names(text: str, name: str, code: int) -> None:
    key = parse_parameter(text)
    assert (key.name, key.code) == (name, code)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("F0.256", "0-255"),
        ("12/0007", "run control"),
        ("16/0000", "not one of 10-15"),
        ("10/0001", "index 0000"),
        ("16-13", "written like"),
        ("", "written like"),
        ("FG.01", "written like"),
    ],
)
def test_bad_parameter_names(text: str, match: str) -> None:
    with pytest.raises(UsageError, match=match):
        parse_parameter(text)


@given(st.sampled_from((10, 11, 13, 15)), st.integers(0, 0xFFFF))
def test_canonical_names_parse_back(command: int, index: int) -> None:
    if command in (10, 15):
        index = 0
    code = command << 16 | index
    assert parse_parameter(format_parameter(code)).code == code


def test_every_running_value_has_an_alias() -> None:
    for index, (alias, _) in RUNNING_VALUES.items():
        assert parse_parameter(alias).code == 0x0B_0000 | index


@pytest.mark.parametrize(
    ("text", "raw", "value", "unit"),
    [
        ("11/0001", 4000, 40.0, "Hz"),  # 0.01 Hz
        ("11/0003", 125, 12.5, "A"),  # 0.1 A
        ("11/0004", 540, 540.0, "V"),
        ("11/000B", 1000, 10.0, "V"),  # 0.01 V
        ("F0.01", 5000, 50.0, "Hz"),
        ("F0.08", 100, 10.0, "s"),  # 0.1 s
        ("F2.17", 5, 5.0, "ms"),
        ("F3.03", 7, 7.0, ""),  # not tabled: raw
    ],
)
def test_value_scaling(text: str, raw: int, value: float, unit: str) -> None:
    spec = lookup(parse_parameter(text).code)
    assert spec.to_value(raw) == pytest.approx(value)
    assert spec.unit == unit
    assert spec.to_raw(value) == raw


def test_positive_exponent_scaling() -> None:
    spec = ValueSpec(name="x", exponent=1)
    assert (spec.to_value(5), spec.to_raw(50.0)) == (50.0, 5)


# ---------------------------------------------------------------- state word (§6)


def test_state_word_bits() -> None:
    assert int(StateWord.RUNNING) == 0x001
    assert int(StateWord.REVERSE) == 0x004
    assert int(StateWord.SPECIFIED_COUNT_REACHED) == 0x400


def test_running_reverse_state_without_fault() -> None:
    assert decode_status(0x0005, 0) == DriveStatus(
        word=5, running=True, fault=False, warning=False, at_reference=False, reverse=True
    )


def test_fault_comes_from_the_failure_index_and_undervoltage_is_the_warning() -> None:
    status = decode_status(int(StateWord.UNDERVOLTAGE), 19)
    assert (status.running, status.fault, status.warning, status.reverse) == (
        False,
        True,
        True,
        False,
    )
