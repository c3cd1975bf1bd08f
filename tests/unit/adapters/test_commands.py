from typing import Any

import pytest

from fcmaster.adapters.commands import parse_command
from fcmaster.bus.commands import Action
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
