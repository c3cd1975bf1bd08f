"""`fcmaster decode`: JSON fields, exit codes 0/1/2, messages on stderr.

Frames and their BCC chains come from tests/unit/protocol/danfoss_fc/test_telegram.py.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from fcmaster.cli import main

REPO = Path(__file__).resolve().parents[2]

START_1 = "02 06 81 04 7C 20 00 DD"  # 02^06=04 ^81=85 ^04=81 ^7C=FD ^20=DD ^00=DD
READ_16_13_REPLY = "02 0E 81 16 4D 00 00 00 00 01 F7 0F 07 20 00 08"
ERROR_17_REPLY = "02 0E 85 71 9E 00 00 00 00 00 11 06 03 00 00 72"

COMMON = {
    "address", "address_format", "broadcast", "telegram", "ak", "ak_name", "parameter",
    "pnu", "index", "pwe", "pcd1", "pcd2", "bcc_ok",
}  # fmt: skip


def run_json(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, dict[str, Any]]:
    code = main(["decode", "--json", *argv])
    captured = capsys.readouterr()
    assert captured.err == ""
    decoded: dict[str, Any] = json.loads(captured.out)
    return code, decoded


def test_request_process_telegram(capsys: pytest.CaptureFixture[str]) -> None:
    code, out = run_json(capsys, *START_1.split())
    assert code == 0
    assert set(out) >= COMMON | {"control", "reference_pct"}
    assert not set(out) & {"status", "output_pct", "error"}
    assert out["address"] == 1
    assert out["address_format"] == 126
    assert out["broadcast"] is False
    assert out["telegram"] == "process"
    assert out["ak"] is None
    assert out["pcd1"] == 0x047C
    assert out["pcd2"] == 0x2000
    assert out["bcc_ok"] is True
    assert out["reference_pct"] == 50.0
    assert out["control"]["start"] is True


def test_response_parameter_telegram(capsys: pytest.CaptureFixture[str]) -> None:
    code, out = run_json(capsys, "--as", "response", READ_16_13_REPLY)
    assert code == 0
    assert set(out) >= COMMON | {"status", "output_pct"}
    assert not set(out) & {"control", "reference_pct", "error"}
    assert out["telegram"] == "parameter"
    assert (out["ak"], out["ak_name"]) == (1, "value_word")
    assert (out["parameter"], out["pnu"], out["index"], out["pwe"]) == ("16-13", 1613, 0, 503)
    assert out["value"]["value"] == pytest.approx(50.3)
    assert out["status"]["running"] is True
    assert out["output_pct"] == 50.0


def test_error_reply_has_code_and_text(capsys: pytest.CaptureFixture[str]) -> None:
    code, out = run_json(capsys, "--as", "response", ERROR_17_REPLY)
    assert code == 0
    assert (out["ak"], out["ak_name"]) == (7, "error")
    assert set(out["error"]) == {"code", "text"}
    assert out["error"]["code"] == 17  # 0x11 on the wire, read as a binary integer
    assert "running" in out["error"]["text"].lower()


@pytest.mark.parametrize(
    "frame",
    [
        pytest.param(["02:06:81:04:7C:20:00:DD"], id="colons"),
        pytest.param(["020681047C2000DD"], id="no-spaces"),
        pytest.param(["02,06,81,04,7c,20,00,dd"], id="commas-lower-case"),
        pytest.param(["0x0206", "81047C2000DD"], id="0x-prefix-split-over-arguments"),
    ],
)
def test_frame_can_be_written_several_ways(
    capsys: pytest.CaptureFixture[str], frame: list[str]
) -> None:
    code, out = run_json(capsys, *frame)
    assert code == 0
    assert (out["pcd1"], out["bcc_ok"]) == (0x047C, True)


def test_wrong_bcc_exits_1_but_still_prints(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["decode", "--json", "02 06 81 04 7C 20 00 DE"])
    captured = capsys.readouterr()
    assert code == 1
    out = json.loads(captured.out)
    assert out["bcc_ok"] is False
    assert out["bcc_expected"] == 0xDD
    assert out["pcd1"] == 0x047C


@pytest.mark.parametrize(
    ("frame", "hint"),
    [
        pytest.param("02 06 81 04 7C 20 00 D", "odd", id="odd-number-of-digits"),
        pytest.param("02 06 81 04 7C 20 00 DG", "'G'", id="non-hex"),
        pytest.param("02 06 81 04", "LGE", id="truncated"),
        pytest.param("02 07 81 04 7C 20 00 DD", "LGE", id="lge-mismatch"),
        pytest.param("03 06 81 04 7C 20 00 DC", "STX", id="no-stx"),
        pytest.param("", "no frame", id="empty"),
    ],
)
@pytest.mark.parametrize("as_json", [True, False], ids=["json", "table"])
def test_bad_input_exits_2_with_a_message_on_stderr(
    capsys: pytest.CaptureFixture[str], frame: str, hint: str, as_json: bool
) -> None:
    code = main(["decode", *(["--json"] if as_json else []), frame])
    captured = capsys.readouterr()
    assert code == 2
    assert captured.out == ""
    assert captured.err.startswith("fcmaster decode: ")
    assert hint in captured.err


def test_table_output_shows_words_in_hex(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["decode", START_1])
    out = capsys.readouterr().out
    assert code == 0
    assert "0x047C" in out
    assert "0x2000" in out
    assert "start" in out


def test_python_dash_m_fcmaster_decode_in_a_subprocess() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "fcmaster", "decode", "--as", "response", "--json",
         *READ_16_13_REPLY.split()],
        cwd=REPO, capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert set(out) >= COMMON | {"status", "output_pct"}
    assert (out["parameter"], out["pwe"], out["bcc_ok"]) == ("16-13", 503, True)


def test_hex_bytes_may_carry_0x_prefixes() -> None:
    from fcmaster.subcommands.frames import parse_hex

    assert parse_hex("0x02 0x06,0x81:04 7C") == bytes([0x02, 0x06, 0x81, 0x04, 0x7C])


def test_mitsubishi_frames_decode_from_ascii_with_control_names(
    capsys: pytest.CaptureFixture[str],
) -> None:
    # The manual's worked example: sum of "01E1107AD" = 0x1F4 → "F4" (protocols/mitsubishi.md §4)
    code = main(["decode", "--protocol", "mitsubishi", "--json", "<ENQ>01E1107ADF4"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert (out["frame"], out["station"], out["instruction"], out["sum_ok"]) == (
        "request",
        1,
        "E1",
        True,
    )


def test_enc_frames_decode_and_a_wrong_checksum_exits_1(
    capsys: pytest.CaptureFixture[str],
) -> None:
    # ~010C00050FA00280: forward run at 40.00 Hz, checksum 0x280 (protocols/enc.md §4.2)
    assert main(["decode", "--protocol", "enc", "--json", "~010C00050FA00280<CR>"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert (out["address"], out["command"], out["cmd_index"], out["data"]) == (1, 12, 5, 4000)
    assert main(["decode", "--protocol", "enc", "--json", "~010C00050FA00281<CR>"]) == 1
    assert json.loads(capsys.readouterr().out)["checksum_ok"] is False
