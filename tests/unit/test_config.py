import json
import textwrap
from pathlib import Path

import pytest

from fcmaster.config import load, parse
from fcmaster.errors import ConfigError

GOOD = """
buses:
  - name: line1
    port: /dev/ttyUSB0
    protocol: danfoss-fc
    baudrate: 19200
    drives:
      - {name: pump-1, address: 1, control: bus, nominal_frequency_hz: 50, max_frequency_hz: 50}
      - {name: pump-2, address: 2, monitor: ["16-13", "16-14"]}
http:
  listen: 127.0.0.1:8080
  tokens:
    - {name: ops, role: operator, token: "${FCM_OPERATOR_TOKEN}"}
"""
ENV = {"FCM_OPERATOR_TOKEN": "0123456789abcdef0123"}


def _problems(text: str, env: dict[str, str] | None = None) -> list[tuple[str, str]]:
    with pytest.raises(ConfigError) as info:
        parse(textwrap.dedent(text), env=ENV if env is None else env)
    return info.value.problems


def test_a_good_config_becomes_line_plans() -> None:
    config = parse(GOOD, env=ENV)
    (line,) = config.lines
    assert line.name == "line1"
    assert line.baudrate == 19200
    assert line.char_bits == 11  # 8E1 by default
    pump1, pump2 = line.drives
    assert pump1.control
    assert not pump2.control  # monitor is the default
    assert pump2.monitor == ("16-13", "16-14")
    assert config.model.http is not None
    assert config.model.http.tokens[0].token == ENV["FCM_OPERATOR_TOKEN"]


def _drive_line(drives: str, extra: str = "") -> str:
    return f"""
buses:
  - name: line1
    port: /dev/ttyUSB0
{extra}    drives:
{drives}
"""


BAD = [
    (
        "duplicate drive names",
        _drive_line("      - {name: a, address: 1}\n      - {name: a, address: 2}"),
        "buses[0].drives[1].name",
        "already used at buses[0].drives[0].name",
    ),
    (
        "duplicate addresses",
        _drive_line("      - {name: a, address: 7}\n      - {name: b, address: 7}"),
        "buses[0].drives[1].address",
        "already used",
    ),
    (
        "address out of range for the 126 format",
        _drive_line("      - {name: a, address: 131}"),
        "buses[0].drives[0].address",
        "131 is outside 1-126",
    ),
    (
        "address out of range for the 31 format",
        _drive_line("      - {name: a, address: 32}", "    address_format: 31\n"),
        "buses[0].drives[0].address",
        "32 is outside 1-31",
    ),
    (
        "unknown protocol",
        _drive_line("      - {name: a, address: 1}", "    protocol: modbus\n"),
        "buses[0].protocol",
        "'modbus' is not one of",
    ),
    (
        "unknown key",
        _drive_line("      - {name: a, address: 1, colour: red}"),
        "buses[0].drives[0].colour",
        "unknown key",
    ),
    (
        "wrong type",
        _drive_line("      - {name: a, address: one}"),
        "buses[0].drives[0].address",
        "integer",
    ),
    (
        "missing port",
        "buses:\n  - name: line1\n    drives: []\n",
        "buses[0].port",
        "required key is missing",
    ),
    (
        "bad parameter name in a monitor list",
        _drive_line('      - {name: a, address: 1, monitor: ["16-13", "sixteen"]}'),
        "buses[0].drives[0].monitor[1]",
        "not written like 16-13",
    ),
    (
        "unset environment variable",
        _drive_line("      - {name: a, address: 1}").replace("/dev/ttyUSB0", "${NO_SUCH_PORT}"),
        "buses[0].port",
        "environment variable NO_SUCH_PORT is not set",
    ),
    (
        "minimum above maximum frequency",
        _drive_line("      - {name: a, address: 1, min_frequency_hz: 60, max_frequency_hz: 50}"),
        "buses[0].drives[0].min_frequency_hz",
        "above the maximum",
    ),
    (
        "a port URL the master cannot open",
        _drive_line("      - {name: a, address: 1}").replace("/dev/ttyUSB0", "tcp://10.0.0.5:4001"),
        "buses[0].port",
        "tcp:// is not a port this master can open (use a device path or sim://, socket://",
    ),
    (
        "an RFC 2217 URL without a port number",
        _drive_line("      - {name: a, address: 1}").replace("/dev/ttyUSB0", "rfc2217://server"),
        "buses[0].port",
        "use rfc2217://host:port (got 'rfc2217://server')",
    ),
    (
        "probes may not take most of the line",
        _drive_line("      - {name: a, address: 1}", "    probe_share: 0.8\n"),
        "buses[0].probe_share",
        "less than or equal to 0.5",
    ),
    (
        "a shutdown that would never end",
        _drive_line("      - {name: a, address: 1}") + "shutdown_timeout_s: 0\n",
        "shutdown_timeout_s",
        "greater than 0",
    ),
    (
        "no buses at all",
        "http: {listen: 127.0.0.1:8080}\n",
        "buses",
        "required key is missing",
    ),
]


@pytest.mark.parametrize(("case", "text", "path", "reason"), BAD, ids=[b[0] for b in BAD])
def test_a_bad_config_names_the_key_and_what_is_wrong(
    case: str, text: str, path: str, reason: str
) -> None:
    problems = _problems(text)
    assert any(p == path and reason in r for p, r in problems), problems


@pytest.mark.parametrize(
    "port", ["/dev/ttyUSB0", "COM3", "socket://10.0.0.5:4001", "rfc2217://ds.local:2217", "sim://x"]
)
def test_device_paths_and_the_urls_the_master_drives_are_accepted(port: str) -> None:
    config = parse(GOOD.replace("/dev/ttyUSB0", port), env=ENV)
    assert config.lines[0].port == port


def test_every_problem_is_reported_at_once() -> None:
    text = _drive_line(
        "      - {name: a, address: 200}\n"
        "      - {name: a, address: 2}\n"
        "      - {name: c, address: 3, monitor: [bogus]}"
    )
    paths = [p for p, _ in _problems(text)]
    assert paths == [
        "buses[0].drives[0].address",
        "buses[0].drives[1].name",
        "buses[0].drives[2].monitor[0]",
    ]


def test_a_duplicated_token_is_reported_without_echoing_the_secret() -> None:
    secret = "s3cret-s3cret-s3cret"
    text = GOOD + f'    - {{name: ops2, role: viewer, token: "{secret}"}}\n'
    text += f'    - {{name: ops3, role: viewer, token: "{secret}"}}\n'
    problems = _problems(text)
    assert problems == [
        ("http.tokens[2].token", "the same token is already used at http.tokens[1].token")
    ]
    assert all(secret not in reason for _, reason in problems)


def test_environment_defaults_apply_when_unset() -> None:
    text = _drive_line("      - {name: a, address: 1}").replace(
        "/dev/ttyUSB0", "${FCM_PORT:-/dev/ttyS1}"
    )
    assert parse(text, env={}).lines[0].port == "/dev/ttyS1"


def test_invalid_yaml_gives_the_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text("buses:\n  - name: [unclosed\n")
    with pytest.raises(ConfigError) as info:
        load(path)
    ((where, reason),) = info.value.problems
    assert where.startswith("line ")
    assert "not valid YAML" in reason


def test_a_missing_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as info:
        load(tmp_path / "absent.yaml")
    assert "cannot read" in info.value.problems[0][1]


@pytest.mark.parametrize(
    "name",
    ["sl/ash", "a+b", "a#b", "two words", "tab\there", "..", ".hidden", "50%", "é", "x" * 65],
)
def test_a_name_no_surface_can_address_is_refused(name: str) -> None:
    drive = f"{{name: {json.dumps(name)}, address: 1}}"
    text = f"buses: [{{name: line1, port: sim://x, drives: [{drive}]}}]"
    with pytest.raises(ConfigError) as caught:
        parse(text)
    [(where, why)] = caught.value.problems
    assert where == "buses[0].drives[0].name"
    assert "cannot be addressed over HTTP and MQTT" in why


@pytest.mark.parametrize("name", ["pump-1", "Line_2", "fan.3", "7", "a" * 64])
def test_plain_names_are_addressable(name: str) -> None:
    quoted = json.dumps(name)
    config = parse(
        f"buses: [{{name: {quoted}, port: sim://x, drives: [{{name: {quoted}, address: 1}}]}}]"
    )
    assert (config.lines[0].name, config.lines[0].drives[0].name) == (name, name)


def test_problems_in_several_buses_and_sections_are_reported_in_one_pass() -> None:
    text = textwrap.dedent(
        """\
        buses:
          - name: hall
            port: /dev/ttyUSB0
            protocol: profibus
          - name: roof
            port: /dev/ttyUSB1
            drives:
              - {name: fan-1, address: 200}
              - {name: fan-2, address: 2, colour: red}
              - {name: fan-1, address: 3, monitor: [bogus]}
          - name: sl/ash
            port: ${FCM_TEST_UNSET}
            baudrate: fast
            drives:
              - {name: mixer, address: 4, min_frequency_hz: 60}
          - name: yard
            port: /dev/ttyUSB2
            drives:
              - {name: fan-9, address: 0}
        http: {listen: 0.0.0.0:8080}
        mqtt: {url: "http://broker"}
        """
    )
    with pytest.raises(ConfigError) as caught:
        parse(text, env={})
    problems = dict(caught.value.problems)
    assert problems.pop("buses[2].port") == "environment variable FCM_TEST_UNSET is not set"
    assert "is not one of" in problems.pop("buses[0].protocol")
    assert problems.pop("buses[1].drives[1].colour") == "unknown key"
    assert "input should be a valid integer" in problems.pop("buses[2].baudrate")
    assert "mqtt.url" in " ".join(problems)
    problems = {k: v for k, v in problems.items() if not k.startswith("mqtt")}
    # the meaning of the well-formed parts, in the same pass
    assert problems == {
        "buses[1].drives[0].address": "200 is outside 1-126",
        "buses[1].drives[2].name": "drive name 'fan-1' is already used at buses[1].drives[0].name",
        "buses[1].drives[2].monitor[0]": problems["buses[1].drives[2].monitor[0]"],
        # sl/ash's wrong baudrate no longer hides the rest of that bus
        "buses[2].name": problems["buses[2].name"],
        "buses[2].drives[0].min_frequency_hz": "60.0 is above the maximum 50.0",
        "buses[3].drives[0].address": "0 is outside 1-126",
        "http.listen": (
            "0.0.0.0:8080 is not a loopback address: with no http.tokens the API is read-only "
            "and served on loopback only; listen on 127.0.0.1 or add tokens"
        ),
    }
    assert "bogus" in problems["buses[1].drives[2].monitor[0]"]
    assert "cannot be addressed over HTTP and MQTT" in problems["buses[2].name"]


def test_a_simulation_section_run_would_refuse_is_refused_by_the_check() -> None:
    text = "buses: [{name: sim1, port: sim://sim1, simulation: {colour: red}}]\n"
    with pytest.raises(ConfigError) as caught:
        parse(text)
    assert caught.value.problems == [("buses.sim1.simulation.colour", "unknown key")]
    drive = "drives: [{name: d1, address: 1}]"
    simulation = "simulation: {response_delay_ms: 1}"  # 8-35 takes 5-10000 ms
    text = f"buses: [{{name: sim1, port: sim://sim1, {drive}, {simulation}}}]"
    with pytest.raises(ConfigError) as caught:
        parse(text)
    [(where, why)] = caught.value.problems
    assert where == "buses.sim1.simulation"
    assert "8-35" in why


@pytest.mark.parametrize(
    "buses",
    [
        "[5, {name: b, port: /dev/ttyUSB1, drives: [{name: x, address: 200}]}]",
        "[{name: a, port: /dev/ttyUSB0, drives: 5}, "
        "{name: b, port: /dev/ttyUSB1, drives: [{name: x, address: 200}]}]",
        "[{name: a, port: /dev/ttyUSB0, drives: [7, {name: y, address: 300}]}]",
    ],
)
def test_odd_shapes_are_reported_with_the_meaning_of_the_rest(buses: str) -> None:
    with pytest.raises(ConfigError) as caught:
        parse(f"buses: {buses}\n")
    paths = [path for path, _ in caught.value.problems]
    assert len(paths) == 2
    assert any(path.endswith(".address") for path in paths)


def _problem_keys(text: str) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse(text)
    return [where for where, _ in caught.value.problems]


def test_a_wrong_key_hides_none_of_the_other_problems_of_its_bus_or_drive() -> None:
    text = textwrap.dedent(
        """\
        buses:
          - name: mb
            port: /dev/ttyUSB0
            protocol: modbus-rtu
            profile: abb-drive
            baudrate: 19000
            drives:
              - {name: y, address: 248, profile: abb-drives}
          - name: fc
            port: /dev/ttyUSB1
            baudrate: 19000
            drives:
              - {name: z, address: 300, nominal_frequency_hz: -5}
              - {name: z, address: 2, watchdog: {timeout_s: 2, when: now}}
              - {name: w, address: 2}
        """
    )
    assert sorted(_problem_keys(text)) == [
        "buses[0].baudrate",
        "buses[0].drives[0].address",
        "buses[0].profile",
        "buses[1].baudrate",
        "buses[1].drives[0].address",
        "buses[1].drives[0].nominal_frequency_hz",
        "buses[1].drives[1].name",  # z again
        "buses[1].drives[1].watchdog.when",
        "buses[1].drives[2].address",  # 2 again
    ]


@pytest.mark.parametrize(
    ("bus", "wrong"),
    [
        ("drives: [{name: d, address: 1, max_frequency_hz: x, min_frequency_hz: 55}]",
         "drives[0].max_frequency_hz"),
        ("protocol: modbus, drives: [{name: d, address: 200}]", "protocol"),
        ("protocol: modbus-rtu, profile: abb-drive, drives: [{name: d, address: 3}]", "profile"),
        ("address_format: 32, drives: [{name: d, address: 100}]", "address_format"),
        ("drives: [{name: d, address: 1, control: bux, watchdog: {timeout_s: 2}}]",
         "drives[0].control"),
        ("baudrate: 9601, drives: [{name: d, address: 1, monitor: 5, control: bus, "
         "watchdog: {timeout_s: 0.1}}]", "drives[0].monitor baudrate"),
        ("drives: [{name: d, address: one}, {name: e, address: 2, control: bus, "
         "watchdog: {timeout_s: 0.1}}]", "drives[0].address"),
        ("drives: [{address: 1}, {name: '', address: 2}]", "drives[0].name drives[1].name"),
    ],
    ids=["maximum", "protocol", "line-profile", "address-format", "control", "monitor",
         "address", "names"],
)  # fmt: skip
def test_a_key_left_out_of_a_broken_bus_or_drive_invents_no_problem(bus: str, wrong: str) -> None:
    # Left out, the key stands at its default: what its checks would say of that is not
    # the user's problem (55 Hz above a default maximum, 200 beyond a default protocol's).
    keys = _problem_keys(f"buses: [{{name: a, port: /dev/ttyUSB0, {bus}}}]")
    assert keys == [f"buses[0].{key}" for key in wrong.split()]
