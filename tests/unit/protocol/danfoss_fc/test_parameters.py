"""Parameter numbers, data types and scaling (protocols/danfoss-fc.md §6.1, §6.5, §7, §10)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fcmaster.errors import MalformedReply, UsageError
from fcmaster.protocol.danfoss_fc import (
    PARAMETERS,
    DataType,
    ParameterSpec,
    RequestAk,
    format_parameter,
    lookup,
    parse_parameter,
)

# ---------------------------------------------------------------- PNU notation (§6.1)


@pytest.mark.parametrize(
    ("text", "pnu"),
    [
        pytest.param("0-01", 0x001, id="0-01"),
        pytest.param("3-41", 0x155, id="3-41"),
        pytest.param("4-14", 0x19E, id="4-14"),
        pytest.param("15-30", 0x5FA, id="15-30"),
        pytest.param("16-13", 0x64D, id="16-13-is-1613-not-0x1613"),
        pytest.param("16-14", 0x64E, id="16-14"),
        pytest.param("16-90", 0x69A, id="16-90"),
        pytest.param("40-95", 0xFFF, id="40-95-is-the-last"),
        pytest.param(" 16-13 ", 0x64D, id="spaces-around"),
        pytest.param("202", 0x0CA, id="legacy-202"),
        pytest.param("615", 0x267, id="legacy-615"),
    ],
)
def test_parameter_number_to_pnu(text: str, pnu: int) -> None:
    assert parse_parameter(text) == pnu


@pytest.mark.parametrize(
    "text",
    [
        pytest.param("41-00", id="41-00-past-12-bits"),
        pytest.param("42-10", id="group-42"),
        pytest.param("99-01", id="group-99"),
        pytest.param("4096", id="legacy-past-12-bits"),
        pytest.param("16-1", id="one-digit-number"),
        pytest.param("16-130", id="three-digit-number"),
        pytest.param("100-00", id="three-digit-group"),
        pytest.param("16.13", id="dot"),
        pytest.param("-5", id="negative"),
        pytest.param("", id="empty"),
        pytest.param("x", id="letter"),
        pytest.param("²", id="superscript-two-is-a-digit-to-isdigit"),
        pytest.param("9" * 5000, id="five-thousand-digits"),
    ],
)
def test_parameter_numbers_that_cannot_be_sent_are_usage_errors(text: str) -> None:
    with pytest.raises(UsageError):
        parse_parameter(text)


def test_41_00_is_refused_with_a_reason() -> None:
    with pytest.raises(UsageError, match="12 bits"):
        parse_parameter("41-00")


@pytest.mark.parametrize(("pnu", "text"), [(1613, "16-13"), (1, "0-01"), (4095, "40-95")])
def test_pnu_to_the_manuals_notation(pnu: int, text: str) -> None:
    assert format_parameter(pnu) == text


@given(st.integers(0, 0xFFF))
def test_every_pnu_survives_format_then_parse(pnu: int) -> None:
    assert parse_parameter(format_parameter(pnu)) == pnu


@given(st.integers(0, 40), st.integers(0, 99))
def test_every_group_and_number_is_100_g_plus_n(group: int, number: int) -> None:
    text = f"{group}-{number:02d}"
    if 100 * group + number <= 4095:
        assert parse_parameter(text) == 100 * group + number
    else:
        with pytest.raises(UsageError):
            parse_parameter(text)


@given(st.text(max_size=12))
@settings(max_examples=300)
def test_parse_parameter_raises_nothing_but_usage_error(text: str) -> None:
    try:
        pnu = parse_parameter(text)
    except UsageError:
        return
    assert 0 <= pnu <= 0xFFF


# ---------------------------------------------------------------- the table (§10)


@pytest.mark.parametrize(
    ("number", "data_type", "conversion"),
    [
        ("3-41", DataType.UINT32, -2),
        ("3-42", DataType.UINT32, -2),
        ("4-12", DataType.UINT16, -1),
        ("4-14", DataType.UINT16, -1),
        ("8-03", DataType.UINT32, -1),
        ("15-00", DataType.UINT32, 74),
        ("15-02", DataType.UINT32, 75),
        ("16-10", DataType.INT32, 1),
        ("16-12", DataType.UINT16, -1),
        ("16-13", DataType.UINT16, -1),
        ("16-14", DataType.INT32, -2),
        ("16-17", DataType.INT32, 67),
        ("16-22", DataType.INT16, 0),
        ("16-30", DataType.UINT16, 0),
        ("16-34", DataType.UINT8, 100),
        ("16-90", DataType.UINT32, 0),
        ("16-92", DataType.UINT32, 0),
        ("16-94", DataType.UINT32, 0),
    ],
)
def test_table_entries_match_the_quick_reference(
    number: str, data_type: DataType, conversion: int
) -> None:
    spec = lookup(parse_parameter(number))
    assert (spec.data_type, spec.conversion, spec.number) == (data_type, conversion, number)


def test_unknown_parameter_has_no_type_and_no_name() -> None:
    spec = lookup(parse_parameter("1-20"))
    assert (spec.data_type, spec.name, spec.pnu) == (None, "", 120)


def test_text_parameters_are_15_40_to_15_53() -> None:
    text_pnus = {pnu for pnu, spec in PARAMETERS.items() if spec.is_text}
    assert text_pnus
    assert all(1540 <= pnu <= 1553 for pnu in text_pnus)


# ---------------------------------------------------------------- value scaling (§7.2)


@pytest.mark.parametrize(
    ("number", "raw", "value", "unit"),
    [
        pytest.param("16-10", 23, 0.23, "kW", id="16-10-index-1-counts-10W-so-23-is-0.23kW"),
        pytest.param("16-14", 524, 5.24, "A", id="16-14-524-is-5.24A"),
        pytest.param("3-41", 1000, 10.0, "s", id="3-41-1000-is-10s"),
        pytest.param("4-14", 1000, 100.0, "Hz", id="4-14-1000-is-100Hz"),
        pytest.param("16-13", 503, 50.3, "Hz", id="16-13-503-is-50.3Hz"),
        pytest.param("16-34", 45, 45.0, "°C", id="16-34-index-100-is-degC-not-scaled"),
        pytest.param("15-00", 12345, 12345.0, "h", id="15-00-index-74-hours-not-times-0.1"),
        pytest.param("15-02", 777, 777.0, "kWh", id="15-02-index-75-kWh-not-scaled"),
        pytest.param("16-17", 1450, 1450.0, "rpm", id="16-17-index-67-rpm-not-scaled"),
        pytest.param("8-35", 10, 10.0, "ms", id="8-35-index-minus-3-in-ms"),
        pytest.param("8-37", 2500, 25.0, "ms", id="8-37-index-minus-5-2500-is-25ms"),
        pytest.param("16-30", 540, 540.0, "V", id="16-30-index-0"),
    ],
)
def test_raw_to_engineering_value(number: str, raw: int, value: float, unit: str) -> None:
    spec = lookup(parse_parameter(number))
    assert spec.unit == unit
    assert spec.to_value(raw) == pytest.approx(value, rel=1e-12)
    assert spec.to_raw(value) == raw


def test_unit_indices_do_not_scale() -> None:
    for conversion in (67, 70, 74, 75, 77, 100):
        spec = ParameterSpec(pnu=1, name="x", data_type=DataType.UINT32, conversion=conversion)
        assert spec.exponent == 0
        assert spec.to_value(12345) == 12345


@pytest.mark.parametrize("conversion", range(-7, 7))
def test_power_of_ten_indices(conversion: int) -> None:
    spec = ParameterSpec(pnu=1, name="x", data_type=DataType.INT32, conversion=conversion)
    assert spec.to_value(3) == pytest.approx(3 * 10.0**conversion, rel=1e-12)


# ---------------------------------------------------------------- widths and signs (§6.5, §7.1)


@pytest.mark.parametrize(
    ("number", "pwe", "double_word", "raw"),
    [
        pytest.param("16-14", 0xFFFF_FFFF, True, -1, id="int32-minus-1"),
        pytest.param("16-14", 0x0000_020C, True, 524, id="int32-524"),
        pytest.param("16-22", 0x0000_FFFF, False, -1, id="int16-minus-1-from-pwelow"),
        pytest.param("16-22", 0xFFFF_FFFF, False, -1, id="int16-ignores-sign-extension"),
        pytest.param("16-22", 0x0000_8000, False, -32768, id="int16-min"),
        pytest.param("16-13", 0x0001_01F7, False, 503, id="uint16-ignores-pwehigh"),
        pytest.param("16-13", 0x0000_FFFF, False, 65535, id="uint16-max"),
        pytest.param("3-41", 0x0000_03E8, False, 1000, id="uint32-read-with-ak-1"),
        pytest.param("3-41", 0x8000_0000, True, 0x8000_0000, id="uint32-top-bit-unsigned"),
        pytest.param("16-34", 0x0000_002D, False, 45, id="uint8"),
        pytest.param("1-20", 0x0001_0002, False, 2, id="unknown-word-by-ak-1"),
        pytest.param("1-20", 0x0001_0002, True, 0x0001_0002, id="unknown-dword-by-ak-2"),
    ],
)
def test_raw_from_pwe_by_data_type(number: str, pwe: int, double_word: bool, raw: int) -> None:
    assert lookup(parse_parameter(number)).raw_from_pwe(pwe, double_word=double_word) == raw


@pytest.mark.parametrize(
    ("number", "raw", "pwe"),
    [
        pytest.param("16-22", -1, 0x0000_FFFF, id="int16-minus-1-only-in-pwelow"),
        pytest.param("16-14", -1, 0xFFFF_FFFF, id="int32-minus-1"),
        pytest.param("4-14", 1000, 0x0000_03E8, id="uint16-1000"),
        pytest.param("3-03", 100_000, 0x0001_86A0, id="int32-100000"),
        pytest.param("1-20", 0x1_0000, 0x0001_0000, id="unknown-over-16-bits"),
    ],
)
def test_pwe_from_raw(number: str, raw: int, pwe: int) -> None:
    assert lookup(parse_parameter(number)).pwe_from_raw(raw) == pwe


@pytest.mark.parametrize(
    ("number", "raw"),
    [
        pytest.param("16-34", 256, id="uint8-over"),
        pytest.param("4-14", -1, id="uint16-negative"),
        pytest.param("4-14", 0x1_0000, id="uint16-over"),
        pytest.param("16-22", 32768, id="int16-over"),
        pytest.param("16-14", 1 << 31, id="int32-over"),
        pytest.param("3-41", 1 << 32, id="uint32-over"),
        pytest.param("15-40", 0, id="text-has-no-value"),
    ],
)
def test_raw_values_the_type_cannot_hold_are_usage_errors(number: str, raw: int) -> None:
    with pytest.raises(UsageError):
        lookup(parse_parameter(number)).pwe_from_raw(raw)


def test_text_parameter_value_is_malformed() -> None:
    with pytest.raises(MalformedReply):
        lookup(parse_parameter("15-40")).raw_from_pwe(0, double_word=False)


@pytest.mark.parametrize(
    ("number", "eeprom", "ak"),
    [
        pytest.param("4-14", True, RequestAk.WRITE_WORD_EEPROM, id="4-14-permanent-is-AK-E"),
        pytest.param("4-14", False, RequestAk.WRITE_WORD, id="4-14-ram-is-AK-2"),
        pytest.param("3-41", True, RequestAk.WRITE_DWORD_EEPROM, id="3-41-permanent-is-AK-D"),
        pytest.param("3-41", False, RequestAk.WRITE_DWORD, id="3-41-ram-is-AK-3"),
        pytest.param("8-04", False, RequestAk.WRITE_WORD, id="uint8-is-a-word"),
    ],
)
def test_write_ak_follows_the_data_type(number: str, eeprom: bool, ak: RequestAk) -> None:
    assert lookup(parse_parameter(number)).write_ak(1, eeprom=eeprom) == ak


def test_request_ak_values_are_the_manuals() -> None:
    assert [int(ak) for ak in RequestAk] == [0x0, 0x1, 0x2, 0x3, 0x4, 0xD, 0xE, 0xF]


_RANGES = {
    DataType.INT16: (-(1 << 15), (1 << 15) - 1),
    DataType.INT32: (-(1 << 31), (1 << 31) - 1),
    DataType.UINT8: (0, 0xFF),
    DataType.UINT16: (0, 0xFFFF),
    DataType.UINT32: (0, 0xFFFF_FFFF),
    DataType.N2: (-(1 << 15), (1 << 15) - 1),
    DataType.V2: (0, 0xFFFF),
}
VALUE_SPECS = [spec for spec in PARAMETERS.values() if not spec.is_text]


@st.composite
def spec_and_raw(draw: st.DrawFn) -> tuple[ParameterSpec, int]:
    spec = draw(st.sampled_from(VALUE_SPECS))
    assert spec.data_type is not None
    low, high = _RANGES[spec.data_type]
    return spec, draw(st.integers(low, high))


@given(spec_and_raw())
@settings(max_examples=300)
def test_every_table_value_survives_the_pwe_both_ways(case: tuple[ParameterSpec, int]) -> None:
    spec, raw = case
    pwe = spec.pwe_from_raw(raw)
    assert 0 <= pwe <= 0xFFFF_FFFF
    if not spec.is_double_word:
        assert pwe <= 0xFFFF, "8 and 16-bit values travel in PWElow with PWEhigh 0"
    # Drives answer 32-bit reads with AK 1 or 2 (§6.3); the data type decides, not the AK.
    for double_word in (False, True):
        assert spec.raw_from_pwe(pwe, double_word=double_word) == raw
    assert spec.to_raw(spec.to_value(raw)) == raw


CONVERSIONS = st.integers(-7, 6) | st.sampled_from([67, 70, 74, 75, 77, 100])


@given(CONVERSIONS, st.integers(-(2**31), 2**32))
def test_every_raw_value_survives_scaling_both_ways(conversion: int, raw: int) -> None:
    spec = ParameterSpec(pnu=1, name="x", data_type=DataType.INT32, conversion=conversion)
    assert spec.to_raw(spec.to_value(raw)) == raw


@given(st.integers(0, 0xFFFF_FFFF), st.booleans())
def test_unknown_parameters_decode_unsigned_by_the_ak(pwe: int, double_word: bool) -> None:
    spec = lookup(parse_parameter("1-20"))
    raw = spec.raw_from_pwe(pwe, double_word=double_word)
    assert raw == (pwe if double_word else pwe & 0xFFFF)
    assert spec.raw_from_pwe(spec.pwe_from_raw(raw), double_word=double_word) == raw


def test_n2_values_scale_by_0x4000_as_100_pct_not_by_conversion_index() -> None:
    # 16-05 is N2 (data type 33): 0x4000 = 100 %, 0xC000 = -100 % (§7.1, §8.5).
    spec = lookup(parse_parameter("16-05"))
    assert spec.to_value(spec.raw_from_pwe(0x4000, double_word=False)) == 100.0
    assert spec.to_value(spec.raw_from_pwe(0xC000, double_word=False)) == -100.0
    assert spec.to_raw(50.0) == 0x2000


def test_an_8_bit_value_with_higher_bits_set_is_malformed_not_masked() -> None:
    spec = lookup(parse_parameter("16-34"))  # Uint8
    with pytest.raises(MalformedReply):
        spec.raw_from_pwe(0x0100, double_word=False)
