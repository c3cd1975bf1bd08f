"""`describe_telegram`: the JSON-ready account of one captured frame."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fcmaster.errors import UsageError
from fcmaster.protocol.danfoss_fc import describe_telegram
from tests.unit.protocol.danfoss_fc.strategies import checked_frames

COMMON = {
    "direction", "address", "address_format", "broadcast", "telegram", "ak", "ak_name",
    "parameter", "parameter_name", "pnu", "index", "pwe", "pcd1", "pcd2", "bcc", "bcc_ok",
}  # fmt: skip

# Frames from test_telegram.py's golden table; BCC chains are written out there.
START_1 = bytes.fromhex("02 06 81 04 7C 20 00 DD")
WRITE_4_14 = bytes.fromhex("02 0E 16 E1 9E 00 00 00 00 03 E8 00 00 00 00 8E")
REPLY_3_41_AK1 = bytes.fromhex("02 0E 81 11 55 00 00 00 00 03 E8 06 03 00 00 27")
REPLY_16_14 = bytes.fromhex("02 0E 81 26 4E 00 00 00 00 02 0C 0F 03 20 00 C7")
ERROR_130 = bytes.fromhex("02 0E 85 71 9E 00 00 00 00 00 82 06 03 00 00 E1")
TEXT_FC_302 = bytes.fromhex("02 10 81 F6 04 04 00 46 43 2D 33 30 32 06 03 00 00 79")


def test_process_request() -> None:
    out = describe_telegram(START_1, from_drive=False)
    assert set(out) == COMMON | {"control", "reference_pct"}
    assert out["telegram"] == "process"
    assert (out["address"], out["address_format"], out["broadcast"]) == (1, 126, False)
    assert (out["ak"], out["pnu"], out["pwe"]) == (None, None, None)
    assert (out["pcd1"], out["pcd2"], out["bcc"], out["bcc_ok"]) == (0x047C, 0x2000, 0xDD, True)
    assert out["reference_pct"] == 50.0
    assert out["control"]["start"] is True
    assert out["control"]["data_valid"] is True
    assert out["control"]["reset"] is False


def test_write_4_14_request_shows_the_scaled_value() -> None:
    out = describe_telegram(WRITE_4_14, from_drive=False)
    assert (out["address"], out["address_format"]) == (22, 31)
    assert (out["ak"], out["ak_name"]) == (0xE, "write_word_eeprom")
    assert (out["parameter"], out["pnu"], out["index"], out["pwe"]) == ("4-14", 414, 0, 1000)
    assert out["value"] == {"raw": 1000, "value": 100.0, "unit": "Hz"}
    assert out["control"]["data_valid"] is False  # a parameter write does not command


def test_3_41_reply_with_ak_1_is_decoded_by_data_type() -> None:
    out = describe_telegram(REPLY_3_41_AK1, from_drive=True)
    assert set(out) == COMMON | {"status", "output_pct", "value"}
    assert (out["ak"], out["ak_name"], out["parameter"]) == (1, "value_word", "3-41")
    assert out["value"] == {"raw": 1000, "value": 10.0, "unit": "s"}


def test_16_14_reply_is_5_24_amps() -> None:
    out = describe_telegram(REPLY_16_14, from_drive=True)
    assert out["value"]["raw"] == 524
    assert out["value"]["value"] == pytest.approx(5.24)
    assert out["value"]["unit"] == "A"
    assert out["status"]["running"] is True
    assert out["output_pct"] == 50.0


def test_error_reply_carries_code_and_text() -> None:
    out = describe_telegram(ERROR_130, from_drive=True)
    assert (out["ak"], out["ak_name"]) == (7, "error")
    assert out["error"]["code"] == 130
    assert "bus access" in out["error"]["text"].lower()
    assert "value" not in out


def test_text_reply() -> None:
    out = describe_telegram(TEXT_FC_302, from_drive=True)
    assert (out["telegram"], out["text"], out["pwe"], out["parameter"]) == (
        "text", "FC-302", None, "15-40",
    )  # fmt: skip


def test_broadcast() -> None:
    # 02^06=04 ^80=84 ^04=80 ^6C=EC ^C0=2C ^00=2C
    out = describe_telegram(bytes.fromhex("02 06 80 04 6C C0 00 2C"), from_drive=False)
    assert (out["address"], out["broadcast"], out["reference_pct"]) == (0, True, -100.0)


def test_wrong_bcc_still_decodes_and_says_what_it_should_be() -> None:
    out = describe_telegram(START_1[:-1] + b"\x00", from_drive=False)
    assert (out["bcc_ok"], out["bcc"], out["bcc_expected"]) == (False, 0x00, 0xDD)
    assert out["pcd1"] == 0x047C


@pytest.mark.parametrize(
    "frame",
    [
        pytest.param(b"", id="empty"),
        pytest.param(b"\x02", id="stx-only"),
        pytest.param(START_1[:5], id="truncated"),
        pytest.param(START_1 + b"\x00", id="longer-than-lge"),
        pytest.param(b"\x03" + START_1[1:], id="no-stx"),
        pytest.param(bytes.fromhex("02 07 81 04 7C 20 00 00 DC"), id="lge-7"),
    ],
)
def test_broken_structure_is_a_usage_error(frame: bytes) -> None:
    with pytest.raises(UsageError):
        describe_telegram(frame, from_drive=False)


@given(st.binary(max_size=40) | checked_frames(), st.booleans())
@settings(max_examples=300)
def test_describe_raises_nothing_but_usage_error(frame: bytes, from_drive: bool) -> None:
    try:
        out = describe_telegram(frame, from_drive=from_drive)
    except UsageError:
        return
    assert set(out) >= COMMON


def test_a_pwe_its_data_type_cannot_carry_is_shown_as_an_error_not_raised() -> None:
    # 16-34 is Uint8; a reply whose PWElow has bits above 8 set carries no valid value.
    body = bytes.fromhex("02 0E 81 16 62 00 00 00 00 01 00 06 03 00 00")
    frame = body + bytes((_xor(body),))
    out = describe_telegram(frame, from_drive=True)
    assert (out["parameter"], out["pwe"], out["bcc_ok"]) == ("16-34", 0x0100, True)
    assert "value" not in out
    assert "8 bits" in out["value_error"]


def _xor(data: bytes) -> int:
    result = 0
    for byte in data:
        result ^= byte
    return result
