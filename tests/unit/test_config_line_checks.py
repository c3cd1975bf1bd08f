"""A config's line settings judged as `run` will use them, and its problems said in words."""

from __future__ import annotations

import io
import textwrap
from pathlib import Path

import pytest

from fcmaster.config import parse
from fcmaster.errors import ConfigError
from fcmaster.subcommands import commission, daemon, ports
from fcmaster.subcommands.commission import LineOptions
from tests.fake_machine import FakeMachine


def _problems(text: str, env: dict[str, str] | None = None) -> list[tuple[str, str]]:
    with pytest.raises(ConfigError) as info:
        parse(textwrap.dedent(text), env=env or {})
    return info.value.problems


@pytest.mark.parametrize(
    ("protocol", "settings"),
    [("danfoss-fc", (9600, "E", 1)), ("mitsubishi", (19200, "E", 2)), ("enc", (9600, "N", 1))],
)
def test_a_bus_without_serial_settings_gets_its_protocols_factory_settings(
    protocol: str, settings: tuple[int, str, int]
) -> None:
    config = parse(f"buses: [{{name: a, port: /dev/ttyUSB0, protocol: {protocol}}}]")
    (line,) = config.lines
    assert (line.baudrate, line.parity, line.stopbits) == settings
    # as the commissioning tools take them with no option given
    plan = LineOptions(port="/dev/ttyUSB0", protocol=protocol).plan()
    assert (plan.baudrate, plan.parity, plan.stopbits) == settings


def test_settings_given_are_kept_and_the_others_are_the_factorys() -> None:
    config = parse("buses: [{name: a, port: /dev/x, protocol: mitsubishi, stopbits: 1}]")
    (line,) = config.lines
    assert (line.baudrate, line.parity, line.stopbits) == (19200, "E", 1)


def test_check_prints_the_settings_each_line_will_use_and_warns_of_absent_ports(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plant = tmp_path / "plant.yaml"
    absent = tmp_path / "ttyUSB9"
    plant.write_text(
        f"buses:\n  - {{name: north, port: {absent}, protocol: enc}}\n"
        "  - {name: south, port: /dev/null, protocol: mitsubishi}\n"
    )
    assert daemon.check(plant, machine=FakeMachine(tmp_path / "root")) == 0
    out = capsys.readouterr().out
    assert f"north: {absent}, enc, 9600 baud 8N1" in out
    assert "south: /dev/null, mitsubishi, 19200 baud 8E2" in out
    assert f"warning: buses[0].port: {absent} does not exist (yet)" in out
    assert "/dev/null does not exist" not in out


@pytest.mark.parametrize("baudrate", [1, 19000, 9999999])
def test_a_baud_rate_the_drives_do_not_offer_is_refused_naming_the_key(baudrate: int) -> None:
    problems = _problems(f"buses: [{{name: a, port: /dev/x, baudrate: {baudrate}}}]")
    assert problems == [
        (
            "buses[0].baudrate",
            f"{baudrate} is not a baud rate danfoss-fc drives offer "
            "(2400, 4800, 9600, 19200, 38400, 57600, 76800, 115200)",
        )
    ]
    # ENC drives stop at 38400
    problems = _problems("buses: [{name: a, port: /dev/x, protocol: enc, baudrate: 115200}]")
    assert problems[0][0] == "buses[0].baudrate"


@pytest.mark.parametrize(
    ("port", "words"),
    [
        ("socket:/10.0.0.5:4001", "write socket://host:port"),
        ("rfc2217:host:4001", "write rfc2217://host:port"),
        ("socket://10.0.0.5", "use socket://host:port"),
        ("ftp:/x", "neither a device path nor a URL"),
    ],
)
def test_a_malformed_port_url_is_refused(port: str, words: str) -> None:
    ((where, reason),) = _problems(f"buses: [{{name: a, port: '{port}'}}]")
    assert where == "buses[0].port"
    assert words in reason


@pytest.mark.parametrize("port", ["/dev/ttyUSB0", "COM3", r"\\.\COM10", "sim://a"])
def test_device_paths_and_urls_that_can_be_opened_pass(port: str) -> None:
    parse(f"buses: [{{name: a, port: '{port}'}}]")


@pytest.mark.parametrize(
    ("text", "where", "words"),
    [
        ("buses:\n  - name: a\n   port: x\n", "line 3, column 4", "indentation does not line up"),
        ("buses:\n\t- name: a\n", "line 2, column 1", "a tab character"),
        ('buses:\n  - name: "a\n    port: x\n', "line 2, column 11", "quote that opens here"),
        ("buses: [a, b\n", "line 1, column 8", "'[' is not closed with ']'"),
        ("buses:\n  - name: a: b\n", "line 2, column 12", "a second ':' on one line"),
        ("buses:\n  - *x\n", "line 2, column 5", "*NAME refers to an anchor &NAME"),
    ],
)
def test_yaml_mistakes_are_said_in_words_with_line_and_column(
    text: str, where: str, words: str
) -> None:
    ((at, reason),) = _problems(text)
    assert at == where
    assert reason.startswith("not valid YAML: ")
    assert words in reason
    assert "<block" not in reason


def test_a_misspelled_key_or_choice_gets_the_nearest_known_one() -> None:
    problems = dict(
        _problems(
            """
            buses:
              - name: a
                port: /dev/x
                prtocol: enc
                drives: [{name: d, address: 1, control: bsu, nominal_frequncy_hz: 50}]
            htpp: {}
            """
        )
    )
    assert problems["buses[0].prtocol"] == "unknown key (did you mean 'protocol'?)"
    assert problems["buses[0].drives[0].control"].endswith("(did you mean 'bus'?)")
    assert problems["buses[0].drives[0].nominal_frequncy_hz"].endswith(
        "(did you mean 'nominal_frequency_hz'?)"
    )
    assert problems["htpp"] == "unknown key (did you mean 'http'?)"


def test_no_secret_is_ever_shown_in_a_problem() -> None:
    problems = _problems(
        """
        buses: [{name: a, port: /dev/x}]
        http:
          tokens: [{name: ops, role: operator, token: hunter2short}]
        mqtt:
          url: mqtt://bob:s3cret-pass@broker
          password: 12
        """
    )
    said = repr(problems)
    for secret in ("hunter2short", "s3cret-pass", "bob:"):
        assert secret not in said
    assert dict(problems)["http.tokens[0].token"].startswith("string should have at least 16")


def test_modbus_map_needs_no_http_secrets(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from fcmaster.subcommands import modbus_map

    plant = tmp_path / "plant.yaml"
    plant.write_text(
        "buses: [{name: a, port: sim://a, drives: [{name: d, address: 1}]}]\n"
        "http: {tokens: [{name: ops, role: operator, token: '${FCM_TEST_UNSET_TOKEN}'}]}\n"
        "modbus: {listen: 127.0.0.1:5020}\n"
    )
    assert modbus_map.run(plant, as_json=False) == 0
    assert "unit 1: d" in capsys.readouterr().out


def test_ports_without_a_config_says_nothing_of_one(tmp_path: Path) -> None:
    machine = FakeMachine(tmp_path / "root")
    machine.add("ttyUSB0", "ftdi_sio", latency_ms=1)
    out = io.StringIO()
    assert ports.run(None, as_json=False, machine=machine, out=out) == 0
    assert "not in the config" not in out.getvalue()
    assert out.getvalue().startswith(f"{machine.dev / 'ttyUSB0'}  ftdi_sio")


def test_a_scan_cut_short_says_nothing_of_addresses_it_never_tried(
    capsys: pytest.CaptureFixture[str],
) -> None:
    options = LineOptions(port="/dev/ttyUSB0")
    commission._print_found([], options, 3, as_json=False, interrupted=True)
    out, err = capsys.readouterr()
    assert out == "no drive answered on /dev/ttyUSB0 before the interrupt\n"
    assert "addresses tried" not in out + err
