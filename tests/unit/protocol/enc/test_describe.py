"""`describe_frame`: the JSON-ready account of one captured ENC frame."""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.errors import UsageError
from fcmaster.protocol.enc import describe_frame
from tests.unit.protocol.enc.strategies import checked_frames, close

COMMON = {
    "direction", "address", "address_field", "address_readings", "broadcast", "command",
    "aux_index", "cmd_index", "index", "data", "checksum", "checksum_ok",
}  # fmt: skip
REPLY = {
    "response", "response_field", "response_readings", "response_text", "failure_index",
    "fault",
}  # fmt: skip

# Frames from test_frame.py and test_codec.py; their checksums are summed there.
FORWARD_40 = b"~010C00050FA00280\r"
WRITE_F0_01 = b"~010E00011388026B\r"
READ_FREQUENCY = b"~010B00010194\r"
STATE_FAULT_10 = b"~0100100F00000258\r"
FRAME_ERROR_HEX = b"~011400C6\r"
COLLIDING_14 = b"~011400000186\r"


def test_run_control_request() -> None:
    out = describe_frame(FORWARD_40, from_drive=False)
    assert set(out) == COMMON | {"command_name", "action", "frequency_hz"}
    assert (out["address"], out["command"], out["aux_index"], out["cmd_index"]) == (1, 12, 0, 5)
    assert (out["index"], out["data"], out["checksum"], out["checksum_ok"]) == (
        "0005",
        4000,
        0x280,
        True,
    )
    assert (out["command_name"], out["action"], out["frequency_hz"]) == (
        "run_control",
        "forward_with_frequency",
        40.0,
    )
    assert out["broadcast"] is False


def test_stop_request_has_no_frequency() -> None:
    out = describe_frame(b"~010C0007019B\r", from_drive=False)
    assert (out["action"], out["data"]) == ("stop", None)
    assert "frequency_hz" not in out


def test_parameter_write_request_shows_the_scaled_value() -> None:
    out = describe_frame(WRITE_F0_01, from_drive=False)
    assert (out["command"], out["parameter"], out["parameter_name"]) == (
        14,
        "F0.01",
        "Run frequency digital setting",
    )
    assert out["value"] == {"raw": 5000, "value": 50.0, "unit": "Hz"}


def test_running_value_request() -> None:
    out = describe_frame(READ_FREQUENCY, from_drive=False)
    assert (out["command_name"], out["parameter"], out["parameter_name"]) == (
        "read_value",
        "11/0001",
        "Running frequency",
    )


def test_broadcast_request() -> None:
    # "7F0C0007": 37+46+30+43 = F0, +30+30+30 = 180, +37 = 1B7
    out = describe_frame(b"~7F0C000701B7\r", from_drive=False)
    assert (out["address"], out["broadcast"]) == (127, True)


def test_unknown_command_and_action_have_no_names() -> None:
    out = describe_frame(close("01200000"), from_drive=False)
    assert (out["command"], out["command_name"]) == (0x20, None)
    out = describe_frame(close("010C00FF"), from_drive=False)
    assert out["action"] is None


def test_reply_with_a_fault() -> None:
    out = describe_frame(STATE_FAULT_10, from_drive=True)
    assert set(out) == COMMON | REPLY
    assert (out["response"], out["response_text"], out["command"]) == (0, "Normal", 0)
    assert (out["aux_index"], out["failure_index"], out["fault"]) == (
        0x10,
        16,
        "RS-485 communication fault",
    )
    assert (out["cmd_index"], out["data"]) == (0x0F, 0)
    decimal = describe_frame(STATE_FAULT_10, from_drive=True, fault_encoding="decimal")
    assert (decimal["failure_index"], decimal["fault"]) == (10, "Inverter overheat")


def test_short_frame_error_reply() -> None:
    out = describe_frame(FRAME_ERROR_HEX, from_drive=True)
    assert (out["response"], out["response_field"]) == (20, "14")
    assert (out["aux_index"], out["cmd_index"], out["index"], out["data"]) == (
        None,
        None,
        None,
        None,
    )
    assert (out["failure_index"], out["fault"]) == (None, None)


def test_the_14_collision_shows_both_readings_and_takes_the_lines() -> None:
    out = describe_frame(COLLIDING_14, from_drive=True)
    assert out["response_readings"] == {"hex": 20, "decimal": 14}
    assert out["response"] == 20
    assert (
        describe_frame(COLLIDING_14, from_drive=True, response_encoding="decimal")["response"] == 14
    )


def test_address_readings() -> None:
    # "1000000F0000": "0"×10 = 1E0, +31+46 = 257
    frame = b"~1000000F00000257\r"
    out = describe_frame(frame, from_drive=True)
    assert (out["address"], out["address_field"], out["address_readings"]) == (
        16,
        "10",
        {"hex": 16, "decimal": 10},
    )
    assert describe_frame(frame, from_drive=True, address_encoding="decimal")["address"] == 10


def test_unreadable_response_code_is_null() -> None:
    out = describe_frame(close("01FF00000000"), from_drive=True)
    assert (out["response"], out["response_text"]) == (None, None)


def test_wrong_checksum_is_reported_not_raised() -> None:
    out = describe_frame(FORWARD_40[:-2] + b"1\r", from_drive=False)
    assert (out["checksum"], out["checksum_ok"], out["checksum_expected"]) == (0x281, False, 0x280)


@pytest.mark.parametrize(
    ("frame", "from_drive", "match"),
    [
        (b"~010c00050FA00280\r", False, "uppercase"),
        (b"~010C00050FA00280", False, "CR"),
        (b"010C00050FA00280\r", False, "~"),
        (b"", True, "~"),
        (FRAME_ERROR_HEX, False, "8 or 12"),
        (close("010C00050"), True, "4 or 8 or 12"),
    ],
    ids=["lowercase", "no-cr", "no-head", "empty", "short-request", "odd-reply"],
)
def test_what_is_not_a_frame_is_a_usage_error(frame: bytes, from_drive: bool, match: str) -> None:
    with pytest.raises(UsageError, match=match):
        describe_frame(frame, from_drive=from_drive)


@given(checked_frames | st.binary(max_size=20), st.booleans())
def test_any_input_gives_json_or_a_usage_error(frame: bytes, from_drive: bool) -> None:
    try:
        out = describe_frame(frame, from_drive=from_drive)
    except UsageError:
        return
    json.dumps(out)
    assert set(out) >= COMMON


def test_software_version_request() -> None:
    out = describe_frame(b"~010F00000197\r", from_drive=False)
    assert (out["command_name"], out["parameter"], out["parameter_name"]) == (
        "software_version",
        "15/0000",
        "Software version",
    )
