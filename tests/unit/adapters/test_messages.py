"""Fleet events as stream messages, and strict JSON."""

from __future__ import annotations

import json

from fcmaster.adapters.messages import event_json, json_safe
from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.hub import EventsDropped
from fcmaster.state import (
    AvailabilityChanged,
    CommandCompleted,
    ConditionChanged,
    DriveState,
    DriveUpdated,
    LineChanged,
)


def test_non_finite_numbers_become_legal_json_at_any_depth() -> None:
    value = {"a": [1.5, float("inf"), {"b": float("-inf")}], "c": float("nan"), "d": (2,)}
    assert json_safe(value) == {"a": [1.5, "+Inf", {"b": "-Inf"}], "c": None, "d": [2]}
    json.dumps(json_safe(value), allow_nan=False)


def test_each_event_has_its_message_type() -> None:
    state = DriveState(name="p", bus="l", address=1, protocol="enc", control="bus")
    command = Command(action=Action.WRITE, parameter="3-41", index=1, value=5.0, actor="ops")
    messages = [
        event_json(DriveUpdated(state)),
        event_json(
            ConditionChanged(bus="l", drive="p", kind="warning", code=3, text="t", active=False)
        ),
        event_json(AvailabilityChanged(bus="l", drive="p", online=False)),
        event_json(
            CommandCompleted(
                bus="l",
                drive="p",
                command=command,
                result=CommandResult(outcome=Outcome.TIMEOUT, reason="r"),
            )
        ),
        event_json(LineChanged(bus="l", up=False, reason="unplugged")),
        event_json(EventsDropped(7)),
    ]
    assert [m["type"] for m in messages] == [
        "drive",
        "condition",
        "availability",
        "command",
        "line",
        "dropped",
    ]
    assert messages[0]["drive"] == state.to_json()
    assert messages[3]["command"] == {
        "action": "write",
        "actor": "ops",
        "parameter": "3-41",
        "index": 1,
        "value": 5.0,
    }
    assert messages[3]["result"] == {"outcome": "timeout", "reason": "r"}
    assert messages[4] == {"type": "line", "bus": "l", "up": False, "reason": "unplugged"}
    assert messages[5] == {"type": "dropped", "count": 7}
