"""Fleet events as JSON messages, and JSON that strict encoders accept.

The WebSocket stream (and anything else that wants them) sends one JSON object per event,
told apart by ``type``:

==============  ===========================================================================
``snapshot``    first message: ``drives`` (every drive state), ``buses`` (every line) and
                ``limits`` (each drive's configured nominal, min and max frequency in Hz)
``drive``       ``drive``: one drive's new state (conflated for slow clients: latest wins),
                ``changed``: the fields that changed since its last message ([]: heartbeat)
``condition``   ``bus``, ``drive``, ``kind`` (alarm/warning), ``code``, ``text``, ``active``
``availability``  ``bus``, ``drive``, ``online``
``command``     ``bus``, ``drive``, ``command`` (action, actor, …) and ``result``
``line``        ``bus``, ``up``, ``reason``, and ``stats`` when sampled
``dropped``     ``count`` discrete events this client missed because it fell behind
==============  ===========================================================================
"""

from __future__ import annotations

import math
from typing import Any

from fcmaster.bus.commands import Command
from fcmaster.hub import EventsDropped
from fcmaster.state import (
    AvailabilityChanged,
    CommandCompleted,
    ConditionChanged,
    DriveUpdated,
    Event,
    LineChanged,
)


def json_safe(value: Any) -> Any:
    """``value`` with non-finite floats made JSON-legal: ±inf → "+Inf"/"-Inf", NaN → None.

    Histogram buckets end at ``le: inf``, which ``json.dumps`` would write as the invalid
    token ``Infinity``; "+Inf" is how Prometheus spells it.
    """
    if isinstance(value, float):
        if math.isfinite(value):
            return value
        if math.isnan(value):
            return None
        return "+Inf" if value > 0 else "-Inf"
    if isinstance(value, dict):
        return {key: json_safe(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(item) for item in value]
    return value


def command_json(command: Command) -> dict[str, Any]:
    """A command as JSON, with who asked for it."""
    out: dict[str, Any] = {"action": command.action.value, "actor": command.actor}
    if command.reference_pct is not None:
        out["reference_pct"] = command.reference_pct
    if command.parameter is not None:
        out["parameter"] = command.parameter
        out["index"] = command.index
    if command.value is not None:
        out["value"] = command.value
    return out


def event_json(event: Event | EventsDropped) -> dict[str, Any]:
    """One event as its stream message (see the module docstring)."""
    match event:
        case DriveUpdated(state=state, changed=changed):
            return {"type": "drive", "drive": state.to_json(), "changed": list(changed)}
        case ConditionChanged():
            return {
                "type": "condition",
                "bus": event.bus,
                "drive": event.drive,
                "kind": event.kind,
                "code": event.code,
                "text": event.text,
                "active": event.active,
            }
        case AvailabilityChanged():
            return {
                "type": "availability",
                "bus": event.bus,
                "drive": event.drive,
                "online": event.online,
            }
        case CommandCompleted():
            return {
                "type": "command",
                "bus": event.bus,
                "drive": event.drive,
                "command": command_json(event.command),
                "result": event.result.to_json(),
            }
        case LineChanged():
            out: dict[str, Any] = {
                "type": "line",
                "bus": event.bus,
                "up": event.up,
                "reason": event.reason,
            }
            if event.stats is not None:
                out["stats"] = event.stats
            return out
        case EventsDropped(count=count):
            return {"type": "dropped", "count": count}
    raise TypeError(f"not a fleet event: {event!r}")  # pragma: no cover - the union is matched
