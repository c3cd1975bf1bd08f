"""Numbers in two-character fields: both readings, the line's choice, and the tables."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.errors import MalformedReply, UsageError
from fcmaster.protocol.codec import Condition, ConditionReport
from fcmaster.protocol.enc import (
    FAULT_TEXTS,
    NumberEncoding,
    ResponseCode,
    encode_number,
    fault_report,
    fault_text,
    number_encoding,
    read_fault,
    read_response,
    readings,
    response_text,
)

HEX, DECIMAL = NumberEncoding.HEX, NumberEncoding.DECIMAL


@pytest.mark.parametrize(
    ("value", "encoding", "field"),
    [
        (1, HEX, 0x01),
        (10, HEX, 0x0A),  # §3: "0A" for 10
        (127, HEX, 0x7F),  # broadcast, §3
        (10, DECIMAL, 0x10),  # the digits "10"
        (20, DECIMAL, 0x20),
        (99, DECIMAL, 0x99),
    ],
)
def test_encode_number(value: int, encoding: NumberEncoding, field: int) -> None:
    assert encode_number(value, encoding) == field


@pytest.mark.parametrize(("value", "encoding"), [(256, HEX), (-1, HEX), (100, DECIMAL)])
def test_numbers_that_do_not_fit_are_usage_errors(value: int, encoding: NumberEncoding) -> None:
    with pytest.raises(UsageError):
        encode_number(value, encoding)


def test_number_encoding_option() -> None:
    assert number_encoding("decimal") is DECIMAL
    with pytest.raises(UsageError, match="hex or decimal"):
        number_encoding("bcd")


def test_readings() -> None:
    assert readings(0x14) == {HEX: 20, DECIMAL: 14}
    assert readings(0x1E) == {HEX: 30}
    assert readings(0x09) == {HEX: 9, DECIMAL: 9}


@given(st.integers(0, 99), st.sampled_from(NumberEncoding))
def test_every_encoded_number_is_among_its_readings(value: int, encoding: NumberEncoding) -> None:
    assert readings(encode_number(value, encoding))[encoding] == value


# ---------------------------------------------------------------- response codes (§5)


@pytest.mark.parametrize(
    ("field", "command", "code"),
    [
        (0x00, 11, ResponseCode.NORMAL),
        (0x14, 12, ResponseCode.FRAME_ERROR),  # hex 20
        (0x20, 12, ResponseCode.FRAME_ERROR),  # printed 20
        (0x1E, 14, ResponseCode.REFUSED),  # hex 30
        (0x30, 14, ResponseCode.REFUSED),  # printed 30
        (0x06, 13, ResponseCode.PARAMETER_NORMAL),  # tables 6 and 7
        (0x0A, 10, ResponseCode.NOT_READY),  # hex 10
        (0x10, 10, ResponseCode.NOT_READY),  # printed 10
        (0x0B, 10, ResponseCode.READY_11),
        (0x11, 10, ResponseCode.READY_11),
        (0x0D, 10, ResponseCode.READY_NO_CONTROL_13),
        (0x13, 10, ResponseCode.READY_NO_CONTROL_13),
        (0x0E, 10, ResponseCode.READY_NO_CONTROL_14),
        (0x20, 10, ResponseCode.FRAME_ERROR),
    ],
)
def test_both_readings_of_response_codes_are_accepted(field: int, command: int, code: int) -> None:
    for encoding in NumberEncoding:
        assert read_response(field, command, encoding) == code


def test_the_14_collision_goes_by_the_line_encoding() -> None:
    # §5: "14" is frame error 20 in hex and "ready, control refused" as printed.
    assert read_response(0x14, 10, HEX) == ResponseCode.FRAME_ERROR
    assert read_response(0x14, 10, DECIMAL) == ResponseCode.READY_NO_CONTROL_14
    # ... unless the reply has no index area, which only a frame error leaves out.
    assert read_response(0x14, 10, DECIMAL, has_index=False) == ResponseCode.FRAME_ERROR
    # For commands 11-15, 14 is not an answer, so "14" can only be hex 20.
    assert read_response(0x14, 11, DECIMAL) == ResponseCode.FRAME_ERROR


@pytest.mark.parametrize(
    ("field", "command"),
    [(0x0A, 11), (0x06, 11), (0x00, 10), (0x30 + 0x01, 12), (0x99, None), (0xFF, 13)],
)
def test_codes_that_do_not_answer_the_command_are_malformed(
    field: int, command: int | None
) -> None:
    with pytest.raises(MalformedReply):
        read_response(field, command, HEX)


def test_response_texts() -> None:
    assert response_text(30).startswith("Refused")
    assert response_text(99) == "Response 99"


# ---------------------------------------------------------------- fault codes (§7)


@pytest.mark.parametrize(
    ("field", "encoding", "code"),
    [
        (0x00, HEX, 0),
        (0x01, HEX, 1),
        (0x0A, DECIMAL, 10),  # only a hex reading: inverter overheat
        (0x10, HEX, 16),  # RS-485 fault in hex …
        (0x10, DECIMAL, 10),  # … inverter overheat as printed
        (0x17, HEX, 23),
        (0x23, HEX, 23),  # hex 35 is no fault; printed 23 is
        (0x19, HEX, 19),  # hex 25 is no fault; printed 19 is
        (0x40, HEX, 0x40),  # neither: kept in the line's reading
        (0x40, DECIMAL, 40),
        (0xAB, DECIMAL, 0xAB),  # no decimal reading at all
    ],
)
def test_fault_codes(field: int, encoding: NumberEncoding, code: int) -> None:
    assert read_fault(field, encoding) == code


def test_fault_texts() -> None:
    assert fault_text(16) == "RS-485 communication fault"
    assert fault_text(11) == "Fault 11"  # reserved
    assert len(FAULT_TEXTS) == 17


def test_fault_report_is_an_alarm_from_the_failure_index() -> None:
    assert fault_report(0) == ConditionReport(kind="alarm", source="failure_index", active=())
    assert fault_report(9).active == (Condition(9, "Motor overload"),)
