"""The commissioning tools' argument handling: what is refused before any port is opened.

Each command here names a port that does not exist: a refusal that came from opening it
would exit 1 with a port error, so exit 2 with the message asserted shows the argument was
judged first.
"""

from __future__ import annotations

import errno
from pathlib import Path

import pytest
import serial

from fcmaster import cli
from fcmaster.cli import build_parser, main
from fcmaster.subcommands import daemon, decode
from fcmaster.transport.open_errors import open_error

NO_PORT = "/nonexistent/ttyUSB9"
CONTROL = ("control", "--port", NO_PORT, "--address", "1")


def subcommands() -> list[str]:
    parser = build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    return sorted(action.choices)  # type: ignore[arg-type]


@pytest.mark.parametrize("command", subcommands())
def test_every_commands_help_prints(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        main([command, "--help"])
    assert exited.value.code == 0
    assert f"usage: fcmaster {command}" in capsys.readouterr().out


def test_control_help_explains_the_reference_in_percent(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit):
        main(["control", "--help"])
    assert "% of the nominal frequency" in capsys.readouterr().out


@pytest.mark.parametrize("timeout", ["0", "-1", "nan", "inf", "soon"])
def test_a_timeout_that_is_not_a_positive_number_is_refused(
    timeout: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["scan", "--port", NO_PORT, "--timeout", timeout])
    assert exited.value.code == 2
    assert "is not a positive number of seconds" in capsys.readouterr().err


def test_a_backwards_address_range_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["sim", "--addresses", "5-1"])
    assert exited.value.code == 2
    assert "'5-1' runs backwards; write 1-5" in capsys.readouterr().err


def test_address_lists_and_ranges_still_parse() -> None:
    args = build_parser().parse_args(["sim", "--addresses", "1-3,7, 9-9"])
    assert args.addresses == [1, 2, 3, 7, 9]


@pytest.mark.parametrize("action", ["stop", "coast", "quick-stop", "reset", "jog"])
@pytest.mark.parametrize("option", [("--frequency", "30"), ("--reference", "60")])
def test_a_reference_given_to_an_action_that_takes_none_is_refused(
    action: str, option: tuple[str, str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*CONTROL, action, *option]) == 2
    assert f"{action} takes no {option[0]}" in capsys.readouterr().err


def test_a_frequency_beyond_the_nominal_with_no_limit_given_names_max_frequency(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main([*CONTROL, "start", "--frequency", "60"]) == 2
    err = capsys.readouterr().err
    assert "60 Hz is beyond the nominal 50 Hz" in err
    assert "--max-frequency" in err
    assert main([*CONTROL, "set-reference", "--reference", "-120"]) == 2
    assert "-60 Hz" in capsys.readouterr().err


def test_with_a_limit_given_the_command_goes_on_to_the_port(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main([*CONTROL, "start", "--frequency", "60", "--max-frequency", "60"]) == 1
    assert f"cannot open {NO_PORT}: no such file or directory" in capsys.readouterr().err


def test_a_missing_device_is_named_once_with_no_dialout_hint(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["scan", "--port", NO_PORT]) == 1
    err = capsys.readouterr().err
    assert err.count("o such file or directory") == 1
    assert "Errno" not in err
    assert "dialout" not in err
    assert "fcmaster ports" in err


def test_a_refused_socket_gets_no_dialout_hint(capsys: pytest.CaptureFixture[str]) -> None:
    from tests.integration.ports import free_port

    port = f"socket://127.0.0.1:{free_port()}"
    assert main(["scan", "--port", port]) == 1
    err = capsys.readouterr().err
    assert f"cannot open {port}: connection refused (nothing listens" in err
    assert "dialout" not in err
    assert "Errno" not in err


def test_a_device_this_user_may_not_open_gets_the_dialout_hint() -> None:
    # As pyserial raises it (the tests run as root, so a real EACCES cannot be made).
    exc = serial.SerialException(
        errno.EACCES, "could not open port /dev/ttyUSB0: [Errno 13] Permission denied"
    )
    assert open_error("/dev/ttyUSB0", exc) == (
        "cannot open /dev/ttyUSB0: permission denied "
        "(this user may not open it: add the user to the dialout group, log in again)"
    )
    assert "dialout" not in open_error("socket://plc:4001", exc)


def test_decode_keeps_a_gap_after_a_long_key(capsys: pytest.CaptureFixture[str]) -> None:
    # ~010C00050FA00280: forward run at 40.00 Hz (protocols/enc.md §4.2)
    assert decode.run("enc", "~010C00050FA00280<CR>", as_response=False, as_json=False) == 0
    rows = capsys.readouterr().out.splitlines()
    readings = next(row for row in rows if row.startswith("address_readings"))
    assert readings.split() == ["address_readings", "hex=1,", "decimal=1"]
    for row in rows:  # every key is followed by at least two spaces, then its value
        key, gap, _ = row.partition("  ")
        assert gap, row
        assert " " not in key, row


def test_run_with_the_demo_config_named_is_the_demo(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[tuple[Path, bool]] = []

    async def fake_run(path: Path, *, demo: bool, http_listen: str | None = None) -> int:
        seen.append((path, demo))
        return 0

    monkeypatch.setattr(daemon, "run", fake_run)
    repo_link = Path(cli.__file__).resolve().parents[1] / "config" / "demo.yaml"
    assert main(["run", "--config", str(repo_link)]) == 0
    assert main(["run"]) == 0
    assert [demo for _, demo in seen] == [True, True]
    other = Path(__file__)
    assert main(["run", "--config", str(other)]) == 0
    assert seen[-1] == (other, False)


def _parameter_set(path: Path, raws: dict[str, int]) -> Path:
    rows = "".join(
        f"  {key}: {{name: {key}, value: {raw}, raw: {raw}}}\n" for key, raw in raws.items()
    )
    path.write_text(
        "format: fcmaster-parameter-set/1\nprotocol: modbus-rtu\naddress: 1\n"
        f"saved_at: '2026-11-29T06:07:57Z'\nidentity: {{}}\nparameters:\n{rows}",
        encoding="utf-8",
    )
    return path


def test_params_diff_of_two_files_counts_the_parameters_of_both(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    left = _parameter_set(tmp_path / "left.yaml", {"hr1": 1, "hr2": 2})
    right = _parameter_set(tmp_path / "right.yaml", {"hr1": 1, "hr3": 3, "hr4": 4})
    assert main(["params", "diff", str(left), str(right)]) == 1
    out = capsys.readouterr().out
    assert [row.split()[0] for row in out.splitlines()[1:-1]] == ["hr2", "hr3", "hr4"]
    assert out.splitlines()[-1] == "3 of 4 parameters differ"  # hr1 to hr4, both files'
    assert main(["params", "diff", str(left), str(left)]) == 0
    assert capsys.readouterr().out == "no differences in 2 parameters\n"
