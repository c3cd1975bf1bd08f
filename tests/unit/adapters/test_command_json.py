import json
import math
import re
from typing import Any

import pytest

from fcmaster.adapters.command_json import BeyondLimits, loads, parse_command, refusal
from fcmaster.bus.commands import Action, Outcome
from fcmaster.bus.plan import DrivePlan
from fcmaster.errors import UsageError

PUMP = DrivePlan(name="pump-1", address=1, control=True, nominal_frequency_hz=60.0)


def test_frequency_becomes_a_reference_of_the_drives_nominal_frequency() -> None:
    command = parse_command({"action": "start", "frequency_hz": 30}, PUMP, actor="ops")
    assert command.action is Action.START
    assert command.reference_pct == 50.0
    assert command.actor == "ops"


def test_read_and_write_carry_parameter_index_and_value() -> None:
    read = parse_command({"action": "read", "parameter": "15-30", "index": 2}, PUMP, actor="x")
    assert (read.parameter, read.index) == ("15-30", 2)
    write = parse_command({"action": "write", "parameter": "3-41", "value": 5}, PUMP, actor="x")
    assert (write.parameter, write.value, write.persist) == ("3-41", 5.0, False)


def test_the_mqtt_id_is_part_of_the_envelope() -> None:
    assert parse_command({"action": "stop", "id": "abc"}, PUMP, actor="m").action is Action.STOP


BAD: list[tuple[Any, str]] = [
    ([1, 2], "JSON object"),
    ({}, "'action' is missing"),
    ({"action": 3}, "'action' is missing or not a string"),
    ({"action": "launch"}, "unknown action 'launch'"),
    ({"action": "stop", "frequency_hz": 10}, "stop does not take 'frequency_hz'"),
    ({"action": "set_reference"}, "needs frequency_hz or reference_pct"),
    ({"action": "start", "frequency_hz": "fast"}, "'frequency_hz' must be a finite number"),
    ({"action": "start", "frequency_hz": True}, "'frequency_hz' must be a finite number"),
    ({"action": "start", "reference_pct": float("nan")}, "must be a finite number"),
    ({"action": "start", "frequency_hz": 1, "reference_pct": 1}, "not both"),
    ({"action": "read"}, "'parameter' is missing"),
    ({"action": "read", "parameter": "16-13", "index": -1}, "'index' must be a whole number"),
    ({"action": "write", "parameter": "3-41"}, "write needs a 'value'"),
    ({"action": "write", "parameter": "3-41", "value": 1, "persist": "yes"}, "'persist'"),
]


@pytest.mark.parametrize(("payload", "reason"), BAD, ids=[r for _, r in BAD])
def test_a_malformed_command_is_refused_with_the_reason(payload: Any, reason: str) -> None:
    with pytest.raises(UsageError, match=reason.replace("(", r"\(")):
        parse_command(payload, PUMP, actor="x")


# -- the input rules every surface shares ----------------------------------------------------

MORE_BAD: list[tuple[Any, str]] = [
    ({"action": "start", "frequency_hz": -40}, "'frequency_hz' is a magnitude (≥ 0), got -40"),
    ({"action": "set_reference", "reference_pct": -0.5}, "'reference_pct' is a magnitude"),
    ({"action": "write", "parameter": "3-41", "value": 1e308}, "'value' is beyond ±1e+12"),
    ({"action": "write", "parameter": "3-41", "value": -(10**400)}, "'value' is beyond ±1e+12"),
    ({"action": "start", "frequency_hz": 1e300}, "'frequency_hz' is beyond"),
    ({"action": "write", "parameter": "3-41", "value": float("inf")}, "finite number"),
]


@pytest.mark.parametrize(("payload", "reason"), MORE_BAD, ids=[r for _, r in MORE_BAD])
def test_negative_huge_and_non_finite_numbers_are_invalid(payload: Any, reason: str) -> None:
    with pytest.raises(UsageError, match=re.escape(reason)) as caught:
        parse_command(payload, PUMP, actor="x")
    assert not isinstance(caught.value, BeyondLimits)
    assert refusal(caught.value).outcome is Outcome.INVALID


def test_minus_zero_is_zero() -> None:
    command = parse_command({"action": "set_reference", "frequency_hz": -0.0}, PUMP, actor="x")
    assert command.reference_pct == 0.0
    assert math.copysign(1.0, command.reference_pct) == 1.0


FIFTY = DrivePlan(name="pump-5", address=5, control=True, max_frequency_hz=50.0)
RANGED = DrivePlan(name="fan-9", address=9, control=True, min_frequency_hz=10.0)


@pytest.mark.parametrize(
    ("payload", "plan", "reason"),
    [
        (
            {"action": "start", "frequency_hz": 50.0000001},
            FIFTY,
            "50.0000001 Hz is beyond pump-5's configured limit of 50 Hz",
        ),
        (
            {"action": "set_reference", "reference_pct": 100.0000002},
            FIFTY,
            "100.0000002 % (50.0000001 Hz) is beyond pump-5's configured limit of 50 Hz",
        ),
        (
            {"action": "start", "frequency_hz": 9.999999999},
            RANGED,
            "9.999999999 Hz is below fan-9's configured minimum of 10 Hz",
        ),
    ],
)
def test_a_reference_beyond_the_limits_is_not_allowed_stated_exactly(
    payload: dict[str, Any], plan: DrivePlan, reason: str
) -> None:
    with pytest.raises(BeyondLimits) as caught:
        parse_command(payload, plan, actor="x")
    result = refusal(caught.value)
    assert (result.outcome, result.reason) == (Outcome.NOT_ALLOWED, reason)


def test_the_limits_themselves_and_a_stop_reference_are_allowed() -> None:
    for hz in (50, 50.0, 0, 0.0):
        assert parse_command({"action": "start", "frequency_hz": hz}, FIFTY, actor="x")
    at_limit = parse_command({"action": "start", "reference_pct": 100}, FIFTY, actor="x")
    assert at_limit.reference_pct == 100.0
    assert parse_command({"action": "start", "frequency_hz": 10}, RANGED, actor="x")
    assert parse_command({"action": "set_reference", "frequency_hz": 0}, RANGED, actor="x")


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ('{"action": "stop", "action": "start"}', "duplicated key 'action'"),
        ('{"a": {"b": 1, "b": 2}}', "duplicated key 'b'"),
        ('{"value": NaN}', "NaN is not a JSON number"),
        ('{"value": -Infinity}', "-Infinity is not a JSON number"),
        ('{"value": 1e400}', "1e400 is beyond what a number can hold"),
    ],
)
def test_json_text_breaking_the_rules_is_refused(text: str, words: str) -> None:
    with pytest.raises(json.JSONDecodeError) as caught:
        loads(text)
    assert caught.value.msg == words


def test_plain_json_text_reads_as_json() -> None:
    assert loads(b'{"action": "start", "frequency_hz": 12.5, "id": [1, {"x": null}]}') == {
        "action": "start",
        "frequency_hz": 12.5,
        "id": [1, {"x": None}],
    }
