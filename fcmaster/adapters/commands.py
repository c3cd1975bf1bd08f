"""Commands as JSON, the same on every surface (DESIGN.md "Commands").

``{"action": A, ...}`` with A one of start, stop, coast, quick_stop, reset, forward,
reverse, jog, set_reference (``frequency_hz`` or ``reference_pct``; start takes them too),
read and write (``parameter``, optional ``index``, and ``value`` for write). Anything else
is refused here, with the reason, before it can reach a line.
"""

from __future__ import annotations

import math
from typing import Any

from fcmaster.bus.commands import Action, Command
from fcmaster.bus.plan import DrivePlan
from fcmaster.errors import UsageError

_KEYS = {
    Action.START: {"frequency_hz", "reference_pct"},
    Action.SET_REFERENCE: {"frequency_hz", "reference_pct"},
    Action.READ: {"parameter", "index"},
    Action.WRITE: {"parameter", "index", "value", "persist"},
}
_ENVELOPE = {"action", "id"}  # "id" is the MQTT correlation id


def parse_command(payload: Any, drive: DrivePlan, *, actor: str) -> Command:
    """A validated :class:`Command` for ``drive``; UsageError says what is wrong."""
    if not isinstance(payload, dict):
        raise UsageError('a command is a JSON object like {"action": "stop"}')
    raw_action = payload.get("action")
    if not isinstance(raw_action, str):
        raise UsageError("'action' is missing or not a string")
    try:
        action = Action(raw_action)
    except ValueError:
        known = ", ".join(a.value for a in Action)
        raise UsageError(f"unknown action {raw_action!r}; known: {known}") from None
    allowed = _KEYS.get(action, set()) | _ENVELOPE
    unknown = sorted(set(payload) - allowed)
    if unknown:
        raise UsageError(f"{action.value} does not take {', '.join(map(repr, unknown))}")

    reference_pct = None
    if "frequency_hz" in payload and "reference_pct" in payload:
        raise UsageError("give frequency_hz or reference_pct, not both")
    if "frequency_hz" in payload:
        hz = _number(payload, "frequency_hz")
        reference_pct = hz / drive.nominal_frequency_hz * 100.0
    elif "reference_pct" in payload:
        reference_pct = _number(payload, "reference_pct")
    if action is Action.SET_REFERENCE and reference_pct is None:
        raise UsageError("set_reference needs frequency_hz or reference_pct")

    parameter = None
    index = 0
    value: float | None = None
    if action in (Action.READ, Action.WRITE):
        parameter = payload.get("parameter")
        if not isinstance(parameter, str | int) or isinstance(parameter, bool):
            raise UsageError("'parameter' is missing; write it as the manual does, e.g. \"16-13\"")
        parameter = str(parameter)
        if "index" in payload:
            index = payload["index"]
            if not isinstance(index, int) or isinstance(index, bool) or index < 0:
                raise UsageError("'index' must be a whole number ≥ 0")
    if action is Action.WRITE:
        if "value" not in payload:
            raise UsageError("write needs a 'value'")
        value = _number(payload, "value")
    persist = payload.get("persist", False)
    if not isinstance(persist, bool):
        raise UsageError("'persist' must be true or false")
    return Command(
        action=action,
        reference_pct=reference_pct,
        parameter=parameter,
        index=index,
        value=value,
        persist=persist,
        actor=actor,
    )


def _number(payload: dict[str, Any], key: str) -> float:
    value = payload[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise UsageError(f"'{key}' must be a finite number, got {value!r}")
    return float(value)
