"""`fcmaster decode --protocol mitsubishi`: the JSON account of one frame."""

from __future__ import annotations

import contextlib
import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.errors import UsageError
from fcmaster.protocol.mitsubishi import (
    Message,
    Terminator,
    describe_frame,
    encode_frame,
    parse_ascii_frame,
)
from tests.unit.protocol.mitsubishi.strategies import messages, terminators


def describe(text: str, *, from_drive: bool = False) -> dict[str, object]:
    return describe_frame(parse_ascii_frame(text), from_drive=from_drive)


def test_manual_request() -> None:
    out = describe("<ENQ>01E1107ADF4<CR>")
    assert out["frame"] == "request"
    assert out["direction"] == "request"
    assert (out["station"], out["instruction"], out["wait_ms"]) == (1, "E1", 10)
    assert (out["access"], out["width"], out["data"]) == ("write", 4, 0x07AD)
    assert (out["sum"], out["sum_ok"], out["terminator"]) == ("F4", True, "cr")
    assert out["error_code"] is None
    assert out["ascii"] == "<ENQ>01E1107ADF4<CR>"
    json.dumps(out)


def test_wrong_sum_is_reported_with_the_right_one() -> None:
    out = describe("<STX>011770<ETX>31", from_drive=True)
    assert (out["frame"], out["data"], out["width"]) == ("data_reply", 0x1770, 4)
    assert (out["sum"], out["sum_ok"], out["sum_expected"]) == ("31", False, "30")
    assert out["instruction"] is None


def test_nak_carries_its_error() -> None:
    out = describe("<NAK>01C<CR><LF>", from_drive=True)
    assert (out["frame"], out["direction"], out["error_code"]) == ("nak", "response", 0xC)
    assert str(out["error_text"]).startswith("Data range error")
    assert (out["sum"], out["sum_ok"], out["terminator"]) == (None, True, "crlf")


def test_ack_direction_comes_from_the_caller() -> None:
    assert describe("<ACK>01", from_drive=True)["direction"] == "response"
    assert describe("<ACK>01", from_drive=False)["direction"] == "request"
    assert describe("<NAK>01")["direction"] == "request"  # the master's NAK has no code


@pytest.mark.parametrize(
    ("body", "key", "value"),
    [
        ("03FA002", "run_command", {"stf": True}),
        ("03ED01388", "frequency_hz", 50.0),
        ("01FD09696", "reset", "no reply"),
        ("01FD09966", "reset", "ACK, then reset"),
        ("01FF001", "page", 1),
        ("01FB00000", "operation_mode", "network"),
        ("01F000000021388", "multi_command", {"send_type": 0, "data1": 2, "data2": 0x1388}),
    ],
)
def test_request_data_is_explained(body: str, key: str, value: object) -> None:
    total = sum(body.encode()) % 256
    out = describe(f"<ENQ>{body}{total:02X}<CR>")
    assert out["sum_ok"] is True
    if isinstance(value, dict):
        explained = out[key]
        assert isinstance(explained, dict)
        assert {k: explained[k] for k in value} == value
    else:
        assert out[key] == value


def test_model_name_reply_has_text() -> None:
    body = "01" + "FR-D720-0.4K".ljust(20)
    total = sum(body.encode()) % 256
    out = describe(f"<STX>{body}<ETX>{total:02X}", from_drive=True)
    assert (out["data"], out["text"], out["width"]) == (None, "FR-D720-0.4K        ", 20)


def test_multi_command_reply_fields() -> None:
    body = "01" + "00FF" + "0082" + "1388"  # s=0 r=0 e1=F e2=F (no error), data1, data2
    total = sum(body.encode()) % 256
    out = describe(f"<STX>{body}<ETX>{total:02X}<CR>", from_drive=True)
    assert out["multi_command"] == {
        "send_type": 0,
        "reply_type": 0,
        "error_code_1": 0xF,
        "error_code_2": 0xF,
        "data1": 0x82,
        "data2": 0x1388,
    }


@pytest.mark.parametrize("text", ["<ENQ>01", "hello", "<STX>0117<ETX>", "<ACK>0", "<ACK>01<LF>"])
def test_what_is_not_a_frame_is_a_usage_error(text: str) -> None:
    with pytest.raises(UsageError):
        describe(text)


@given(messages, terminators)
def test_every_encoded_message_describes_with_a_good_sum(
    message: Message, terminator: Terminator
) -> None:
    out = describe_frame(encode_frame(message, terminator), from_drive=True)
    assert out["sum_ok"] is True
    assert out["station"] == message.station
    json.dumps(out)


@given(st.binary(max_size=30))
def test_describe_raises_only_usage_error(data: bytes) -> None:
    with contextlib.suppress(UsageError):
        describe_frame(data, from_drive=True)
