"""Drive profiles: the built-ins hold together, registers scale both ways, user files are
checked with every problem named."""

from __future__ import annotations

import dataclasses

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.errors import ConfigError, UsageError
from fcmaster.protocol.modbus_rtu.keys import parse_register
from fcmaster.protocol.modbus_rtu.parameter_tables import members, tables_of
from fcmaster.protocol.modbus_rtu.profile import (
    Register,
    StateMachine,
    checked,
    profile_problems,
)
from fcmaster.protocol.modbus_rtu.profile_file import parse_profile_text
from fcmaster.protocol.modbus_rtu.profiles import BUILT_IN
from fcmaster.protocol.registry import spec_for

DESIGN_NAMES = [
    "abb-drives",
    "sinamics-v20",
    "altivar-cia402",
    "yaskawa-memobus",
    "danfoss-fc-modbus",
]

# The example of DESIGN "Drive profiles", with numbers where it has dots.
USER_PROFILE = """
name: my-vfd
registers:
  control: {address: 256}
  reference: {address: 257, scale: 0.01, unit: Hz}
  status: {address: 512}
  output_frequency: {address: 513, scale: 0.01, unit: Hz}
  fault_code: {address: 514}
commands:
  start: [6, 7]
  stop: [1]
status_bits: {running: 8, fault: 9}
faults: {770: "Overcurrent"}
watchdog:
  timeout: {address: 600, scale: 0.1}
  action: {address: 601}
  actions: {0: {action: "off", stops: false}, 1: {action: "trip", stops: true}}
values: [{name: "Motor Current", address: 515, scale: 0.1, unit: A}]
"""


def problems_of(text: str) -> dict[str, str]:
    with pytest.raises(ConfigError) as caught:
        parse_profile_text(text, "my.yaml: ")
    return dict(caught.value.problems)


# ---------------------------------------------------------------- the built-ins


def test_the_built_in_profiles_are_the_ones_design_names() -> None:
    assert list(BUILT_IN) == DESIGN_NAMES


@pytest.mark.parametrize("name", DESIGN_NAMES)
def test_each_built_in_is_sound_and_cites_its_manuals(name: str) -> None:
    profile = BUILT_IN[name]
    assert profile_problems(profile) == []
    assert profile.sources
    # What no manual page confirmed is said in the profile, not passed off as checked.
    cited = any("p." in s for s in profile.sources)
    assert cited or any("not checked" in u for u in profile.unverified)
    assert profile.faults
    assert profile.watchdog.registers, "the audit needs the watchdog's registers"
    assert {"start", "stop", "reset"} <= set(profile.commands)


def test_the_cia402_profile_walks_the_state_machine() -> None:
    altivar = BUILT_IN["altivar-cia402"]
    assert altivar.state_machine is StateMachine.CIA402
    assert altivar.commands["start"] == (0x06, 0x07, 0x0F)


@pytest.mark.parametrize("name", ["abb-drives", "sinamics-v20"])
def test_profidrive_profiles_clear_off1_before_running(name: str) -> None:
    start = BUILT_IN[name].commands["start"]
    assert start[-2] & 0x0F == 0x0E
    assert start[-1] & 0x0F == 0x0F


def test_a_state_machine_start_without_its_sequence_is_refused() -> None:
    altivar = BUILT_IN["altivar-cia402"]
    broken = dataclasses.replace(altivar, commands={**altivar.commands, "start": (0x0F,)})
    with pytest.raises(ConfigError, match="enable sequence"):
        checked(broken)
    abb = BUILT_IN["abb-drives"]
    with pytest.raises(ConfigError, match="OFF1"):
        checked(dataclasses.replace(abb, commands={**abb.commands, "start": (0x047F,)}))


def test_a_profile_that_can_reverse_but_never_tells_the_direction_is_refused() -> None:
    yaskawa = BUILT_IN["yaskawa-memobus"]  # a reverse run; its output frequency a magnitude
    bits = {k: v for k, v in yaskawa.status_bits.items() if k != "reverse"}
    blind = dataclasses.replace(yaskawa, status_bits=bits)
    assert [path for path, _ in profile_problems(blind)] == ["status_bits.reverse"]
    signed = Register(address=0x0024, scale=0.01, unit="Hz", signed=True)
    assert profile_problems(dataclasses.replace(blind, output_frequency=signed)) == []
    forward_only = {k: v for k, v in yaskawa.commands.items() if k != "start_reverse"}
    assert profile_problems(dataclasses.replace(blind, commands=forward_only)) == []


# ---------------------------------------------------------------- watchdogs and faults


def test_abb_watchdog_settings() -> None:
    watchdog = BUILT_IN["abb-drives"].watchdog
    fault = watchdog.setting([3.0, 1])
    assert (fault.timeout_s, fault.action, fault.stops) == (3.0, "fault", True)
    assert watchdog.setting([3.0, 0]).stops is False
    assert watchdog.setting([3.0, 2]).action == "last speed"


def test_altivar_sll_options_the_readings_disagree_on_are_not_taken_as_a_stop() -> None:
    watchdog = BUILT_IN["altivar-cia402"].watchdog
    assert watchdog.setting([2.0, 1]).stops is True  # freewheel
    assert watchdog.setting([2.0, 2]).stops is True  # ramp stop, or Stt (a ramp by default)
    assert watchdog.setting([2.0, 0]).stops is False  # ignore
    # fast stop or fallback speed; speed maintained or ramp stop: the verdict stays unknown
    assert watchdog.setting([2.0, 3]).stops is None
    assert watchdog.setting([2.0, 5]).stops is None
    assert watchdog.setting([2.0, 7]).stops is None  # no reading for it at all


def test_v20_watchdog_is_off_at_zero() -> None:
    watchdog = BUILT_IN["sinamics-v20"].watchdog
    assert watchdog.setting([0.0]).timeout_s is None
    on = watchdog.setting([0.5])
    assert (on.timeout_s, on.stops) == (0.5, True)


def test_yaskawa_watchdog_is_off_when_detection_is_disabled() -> None:
    watchdog = BUILT_IN["yaskawa-memobus"].watchdog
    assert watchdog.setting([2.0, 1, 0]).action == "off"
    assert watchdog.setting([2.0, 1, 1]).action == "coast to stop"
    assert watchdog.setting([2.0, 3, 1]).stops is False


def test_danfoss_watchdog_reads_as_the_fc_line_does() -> None:
    watchdog = BUILT_IN["danfoss-fc-modbus"].watchdog
    assert watchdog.setting([1.0, 2]).action == "stop"
    assert watchdog.setting([1.0, 0]).timeout_s is None


def test_fault_texts_by_code_and_by_bit() -> None:
    assert BUILT_IN["altivar-cia402"].fault_texts(9) == [(9, "OCF Overcurrent")]
    assert BUILT_IN["altivar-cia402"].fault_texts(0) == []
    assert BUILT_IN["abb-drives"].fault_texts(1234) == [(1234, "Fault 1234")]
    danfoss = BUILT_IN["danfoss-fc-modbus"]
    assert danfoss.fault_texts(1 << 5 | 1 << 11) == [(5, "Over current"), (11, "DC over-voltage")]


# ---------------------------------------------------------------- registers


@given(st.integers(-0x8000, 0x7FFF))
def test_a_signed_register_round_trips(raw: int) -> None:
    register = Register(address=1, scale=0.01, unit="Hz", signed=True)
    words = register.raw(raw * 0.01)
    assert register.value(words) == pytest.approx(raw * 0.01)
    assert 0 <= words[0] <= 0xFFFF


@given(st.integers(0, 0xFFFFFFFF))
def test_a_two_word_register_is_high_word_first(raw: int) -> None:
    register = Register(address=1, words=2)
    words = register.raw(raw)
    assert words == (raw >> 16, raw & 0xFFFF)
    assert register.value(words) == raw


@pytest.mark.parametrize("value", [-0.01, 655.36, float("nan"), float("inf")])
def test_a_value_a_register_cannot_hold_is_refused_not_clamped(value: float) -> None:
    with pytest.raises(UsageError):
        Register(address=7, scale=0.01, unit="Hz").raw(value)


# ---------------------------------------------------------------- user profile files


def test_the_design_example_reads() -> None:
    profile = parse_profile_text(USER_PROFILE)
    assert profile.name == "my-vfd"
    assert profile.reference == Register(address=257, scale=0.01, unit="Hz")
    assert profile.commands == {"start": (6, 7), "stop": (1,)}
    assert profile.faults == {770: "Overcurrent"}
    assert profile.values[0].name == "Motor Current"
    assert profile.values[0].register.address == 515
    assert profile.watchdog.setting([2.0, 1]).stops is True


def test_a_cia402_profile_without_its_enable_sequence_is_refused() -> None:
    text = USER_PROFILE.replace("name: my-vfd", "name: my-vfd\nstate_machine: cia402")
    problems = problems_of(text.replace("start: [6, 7]", "start: [15]"))
    assert "enable sequence" in problems["my.yaml: commands.start"]
    parse_profile_text(text.replace("start: [6, 7]", "start: [6, 7, 15]"))


def test_every_problem_is_named_at_once() -> None:
    text = (
        USER_PROFILE.replace("{address: 512}", "{address: 70000}")
        .replace("unit: Hz}\n  status", "unit: rpm}\n  status")
        .replace("stop: [1]", "halt: [1]")
        .replace("fault: 9", "fault: 16")
        .replace("scale: 0.1, unit: A", "scale: 0.1, unit: A, colour: red")
    )
    problems = problems_of(text)
    assert set(problems) == {
        "my.yaml: registers.status.address",
        "my.yaml: registers.reference.unit",
        "my.yaml: commands.stop",
        "my.yaml: commands.halt",
        "my.yaml: status_bits.fault",
        "my.yaml: values[0].colour",
    }


def test_missing_and_mistyped_keys() -> None:
    problems = problems_of("name: 7\nregisters: {control: {}}\ncommands: {start: oops}\nwho: me\n")
    assert "text" in problems["my.yaml: name"]
    assert problems["my.yaml: registers.control.address"] == "missing"
    assert problems["my.yaml: registers.status"] == "missing"
    assert "control words" in problems["my.yaml: commands.start"]
    assert "unknown key" in problems["my.yaml: who"]


def test_not_yaml_and_not_a_mapping() -> None:
    assert any("not valid YAML" in r for r in problems_of("name: [").values())
    assert "mapping" in problems_of("- 1\n")["my.yaml: (top)"]


# ---------------------------------------------------------------- the audit's facts


def test_each_drives_watchdog_facts_come_from_its_profile() -> None:
    spec = spec_for("modbus-rtu")
    abb = spec.drive_watchdog(None, BUILT_IN["abb-drives"])
    assert abb.parameters == ("hr5815", "hr5813")
    assert abb.encode(3.0, "fault") == (("hr5815", 3.0), ("hr5813", 1))
    assert abb.decode([3.0, 4]).action == "fault always"
    assert "hr5815" in abb.advice(2.0)
    yaskawa = spec.drive_watchdog(None, BUILT_IN["yaskawa-memobus"])
    assert yaskawa.encode(2.0, "ramp to stop") == (("hr1077", 2.0), ("hr1064", 0), ("hr1065", 1))
    v20 = spec.drive_watchdog(None, BUILT_IN["sinamics-v20"])
    assert v20.actions == ("fault F72",)
    assert v20.timeout_range_s == (0.1, 65.535)
    with pytest.raises(UsageError):
        abb.encode(3.0, "warning")  # an action that lets the motor run is never written
    # A drive without a profile has the line's facts, which read nothing.
    assert spec.drive_watchdog(None, None).parameters == ()


def test_a_watchdog_action_register_without_its_meanings_reads_as_unknown() -> None:
    # DESIGN's own example names the action register and not what its values mean.
    text = USER_PROFILE.replace(
        '  actions: {0: {action: "off", stops: false}, 1: {action: "trip", stops: true}}\n', ""
    )
    setting = parse_profile_text(text).watchdog.setting([2.0, 1])
    assert (setting.timeout_s, setting.action, setting.stops) == (2.0, "option 1", None)


def test_a_profiles_settings_make_up_its_parameter_set_then_its_watchdog() -> None:
    text = USER_PROFILE + (
        'parameters: [{name: "Acceleration", address: 600, scale: 0.1, unit: s},\n'
        '             {name: "Deceleration", address: 602, scale: 0.1, unit: s}]\n'
    )
    profile = parse_profile_text(text)
    assert [v.name for v in profile.parameters] == ["Acceleration", "Deceleration"]
    # 600 is the watchdog's timeout too: one member, under the setting's name
    assert members(profile) == (
        ("hr600", "Acceleration"),
        ("hr602", "Deceleration"),
        ("hr601", "Communication watchdog action"),
    )
    tables = tables_of(profile)
    assert tables.unit_of(parse_register("hr602")) == "s"
    assert tables.unit_of(parse_register("hr515")) == "A"  # a monitored value's unit too
    assert tables_of(None).set_members == ()
    found = problems_of(
        USER_PROFILE + "parameters: [{name: x, address: 3, input: true}, {address: 4}]\n"
    )
    assert found["my.yaml: parameters[0].input"] == "a setting is a holding register"
    assert "not None" in found["my.yaml: parameters[1].name"]
