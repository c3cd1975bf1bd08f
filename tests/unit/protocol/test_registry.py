"""The protocol registry: one spec per protocol, read by config, CLI, commissioning and sim."""

from __future__ import annotations

import ast
import dataclasses
import textwrap
from pathlib import Path

import pytest

import fcmaster
from fcmaster.bus.plan import LinePlan
from fcmaster.cli import build_parser, main
from fcmaster.config import BusModel, parse
from fcmaster.errors import ConfigError, UsageError
from fcmaster.protocol.registry import DEFAULT, NAMES, PROTOCOLS, line_keys, spec_for
from fcmaster.protocol.spec import KeyValue, LineKey
from fcmaster.sim.build import SIM_PROTOCOLS
from fcmaster.sim.settings import LineSettings
from fcmaster.subcommands import commission
from fcmaster.subcommands.commission import LineOptions

PACKAGE = Path(fcmaster.__file__).parent


def test_the_registry_lists_the_four_protocols_with_danfoss_fc_first() -> None:
    assert NAMES == ("danfoss-fc", "mitsubishi", "enc", "modbus-rtu")
    assert DEFAULT == "danfoss-fc"


@pytest.mark.parametrize("name", NAMES)
def test_each_spec_builds_a_codec_of_its_own_protocol(name: str) -> None:
    assert spec_for(name).codec().protocol == name


def test_an_unknown_protocol_is_refused_with_the_known_ones() -> None:
    with pytest.raises(UsageError, match=r"'profibus' is not supported \(have: danfoss-fc, "):
        spec_for("profibus")


@pytest.mark.parametrize(
    ("options", "first", "last"),
    [
        pytest.param(LineOptions(port="p"), 1, 126, id="fc-126"),
        pytest.param(
            LineOptions(port="p", protocol_options=(("address_format", 31),)), 1, 31, id="fc-31"
        ),
        pytest.param(LineOptions(port="p", protocol="mitsubishi"), 0, 31, id="mitsubishi"),
        pytest.param(LineOptions(port="p", protocol="enc"), 1, 126, id="enc-hex"),
        pytest.param(
            LineOptions(
                port="p", protocol="enc", protocol_options=(("address_encoding", "decimal"),)
            ),
            1, 99, id="enc-decimal",
        ),
    ],
)  # fmt: skip
def test_scan_by_default_tries_the_addresses_the_spec_gives_for_the_line(
    options: LineOptions, first: int, last: int
) -> None:
    spec = spec_for(options.protocol)
    assert spec.addresses(options) == range(first, last + 1)
    # what `scan` walks without --addresses: the codec of the plan its options make
    assert spec.codec(options.plan()).addresses == range(first, last + 1)


def test_a_source_without_a_key_takes_its_default() -> None:
    enc = spec_for("enc")
    decimal = LineSettings(protocol="enc", protocol_options=(("address_encoding", "decimal"),))
    assert enc.addresses(decimal) == range(1, 100)
    assert spec_for("danfoss-fc").addresses(LineSettings()) == range(1, 127)  # no format there


def test_factory_settings_fill_what_the_command_line_leaves_out() -> None:
    plans = {name: LineOptions(port="p", protocol=name).plan() for name in NAMES}
    got = {name: (p.baudrate, p.parity, p.stopbits) for name, p in plans.items()}
    assert got == {
        "danfoss-fc": (9600, "E", 1),
        "mitsubishi": (19200, "E", 2),
        "enc": (9600, "N", 1),
        "modbus-rtu": (19200, "E", 1),  # Modbus over Serial Line §2.5.1: even parity
    }


def test_every_line_key_is_a_config_key_and_a_cli_option_with_its_default() -> None:
    scan = build_parser().parse_args(["scan", "--port", "p"])
    for key, spec in line_keys():
        assert key.name in BusModel.model_fields, key.name
        assert BusModel.model_fields[key.name].default == key.default
        assert getattr(scan, key.name) == key.default, key.name
        assert key.name in {f.name for f in dataclasses.fields(spec.options)}  # type: ignore[arg-type]
        if key.simulated:  # the simulated line carries it with no field of its own
            assert key.name not in {f.name for f in dataclasses.fields(LineSettings)}
            value = _other_value(key)
            line = LineSettings(protocol=spec.name, protocol_options=((key.name, value),))
            assert getattr(spec.options_of(line), key.name) == value


def _other_value(key: LineKey) -> KeyValue:
    if key.choices:
        return next(c for c in key.choices if c != key.default)
    return key.maximum


@pytest.mark.parametrize(
    ("key", "name"), [(k, s.name) for k, s in line_keys()], ids=[k.name for k, _ in line_keys()]
)
def test_a_line_key_in_the_config_reaches_the_codec_options(key: LineKey, name: str) -> None:
    value = _other_value(key)
    text = f"""
    buses:
      - name: a
        port: /dev/ttyUSB0
        protocol: {name}
        {key.name}: {value}
    """
    (plan,) = parse(textwrap.dedent(text), env={}).lines
    assert getattr(spec_for(name).options_of(plan), key.name) == value


@pytest.mark.parametrize(
    ("key", "name"), [(k, s.name) for k, s in line_keys()], ids=[k.name for k, _ in line_keys()]
)
def test_a_line_key_on_the_command_line_reaches_the_commissioning_codec(
    key: LineKey, name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # No field of LineOptions names the key: the CLI hands it over as one of the protocol's
    # options, and the plan commissioning opens the port with carries it to the codec.
    given: list[LineOptions] = []

    async def scan(options: LineOptions, addresses: object, *, as_json: bool) -> int:
        given.append(options)
        return 0

    monkeypatch.setattr(commission, "scan", scan)
    value = _other_value(key)
    flag = "--" + key.name.replace("_", "-")
    assert main(["scan", "--port", "p", "--protocol", name, flag, str(value)]) == 0
    (options,) = given
    assert getattr(spec_for(name).options_of(options.plan()), key.name) == value
    assert key.name not in {f.name for f in dataclasses.fields(LineOptions)}


def test_commissioning_refuses_options_its_protocol_does_not_have() -> None:
    with pytest.raises(UsageError, match="enc lines have no address_format"):
        LineOptions(port="p", protocol="enc", protocol_options=(("address_format", 31),))
    with pytest.raises(UsageError, match="address_format 32 is not 31 or 126"):
        LineOptions(port="p", protocol_options=(("address_format", 32),))


def test_a_plan_carries_keys_it_has_no_field_for_to_the_spec() -> None:
    @dataclasses.dataclass(frozen=True)
    class Options:
        unit_offset: int = 0

    spec = dataclasses.replace(
        spec_for("danfoss-fc"),
        options=Options,
        line_keys=(LineKey(name="unit_offset", default=0, minimum=0, maximum=9, help=""),),
    )
    plan = LinePlan(name="a", port="p", protocol_options=(("unit_offset", 7),))
    assert spec.options_of(plan) == Options(unit_offset=7)
    assert spec.options_of(LinePlan(name="a", port="p")) == Options()


def test_a_protocols_own_number_option_is_checked_on_the_command_line(
    capsys: pytest.CaptureFixture[str],
) -> None:
    parser = build_parser()
    args = parser.parse_args(["scan", "--port", "p", "--wait-time-ms", "none"])
    assert args.wait_time_ms is None
    with pytest.raises(SystemExit):
        parser.parse_args(["scan", "--port", "p", "--wait-time-ms", "15"])
    assert "'15' is not 0-150 in steps of 10, or none" in capsys.readouterr().err


def test_a_key_of_another_protocol_is_named_with_the_protocol_that_has_it() -> None:
    text = """
    buses:
      - name: a
        port: /dev/ttyUSB0
        protocol: enc
        address_format: 31
        terminator: crlf
        address_encoding: decimal
    """
    with pytest.raises(ConfigError) as info:
        parse(textwrap.dedent(text), env={})
    assert info.value.problems == [
        ("buses[0].address_format", "only danfoss-fc lines have one"),
        ("buses[0].terminator", "only mitsubishi lines have one"),
    ]


def test_the_simulator_has_drives_for_every_registered_protocol() -> None:
    assert set(SIM_PROTOCOLS) == set(PROTOCOLS)


# Modules that used to branch on the vendor and now read the spec: a protocol id written
# as a string in them would be a branch come back.
READS_THE_SPEC = (
    "config.py",
    "cli.py",
    "cli_arguments.py",
    "bus/codecs.py",
    "bus/confirm.py",
    "sim/build.py",
    "adapters/discovery.py",
    "subcommands/decode.py",
    "subcommands/diagnosis.py",
    "subcommands/doctor.py",
)


@pytest.mark.parametrize("module", READS_THE_SPEC)
def test_modules_that_read_the_spec_never_name_a_protocol(module: str) -> None:
    tree = ast.parse((PACKAGE / module).read_text(encoding="utf-8"))
    named = [
        (node.lineno, node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        # docstrings may give an example; code may not compare with one
        and node.value in NAMES
    ]
    assert named == []
