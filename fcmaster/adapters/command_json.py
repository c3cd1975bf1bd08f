"""Commands as JSON, the same on every surface (DESIGN.md "Commands").

``{"action": A, ...}`` with A one of start, stop, coast, quick_stop, reset, forward,
reverse, jog, set_reference (``frequency_hz`` or ``reference_pct``; start takes them too),
read and write (``parameter``, optional ``index``, and ``value`` for write). Anything else
is refused here, with the reason, before it can reach a line.

These are the input rules of every surface (HTTP, MQTT, Modbus), kept in this one place:

- JSON text is read by :func:`loads`, which refuses a duplicated key (a proxy or a log that
  reads the first ``"action"`` must see what runs) and the non-standard NaN and Infinity;
- every number is finite and at most :data:`MAX_MAGNITUDE` before any arithmetic is done
  with it, so ``1e308`` is ``invalid``, never an overflow further down;
- frequencies and references are magnitudes (≥ 0): direction changes only by forward and
  reverse, so a negative number is ``invalid``;
- a reference beyond the drive's configured limits is :class:`BeyondLimits`
  (``not_allowed``), compared exactly (as fractions, no tolerance) and stated with the
  number as given: 50.0000001 Hz is beyond 50 Hz, and the reason says 50.0000001.

:func:`refusal` turns what :func:`parse_command` raises into the command's one result.
"""

from __future__ import annotations

import json
import math
from fractions import Fraction
from typing import Any, Final

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.bus.plan import DrivePlan
from fcmaster.errors import UsageError
from fcmaster.protocol.drive import hz_to_pct, pct_to_hz

_KEYS = {
    Action.START: {"frequency_hz", "reference_pct"},
    Action.SET_REFERENCE: {"frequency_hz", "reference_pct"},
    Action.READ: {"parameter", "index"},
    Action.WRITE: {"parameter", "index", "value", "persist"},
}
_ENVELOPE = {"action", "id"}  # "id" is the MQTT correlation id
# Beyond any value a drive parameter or a reference can hold (32-bit registers, scaled),
# and small enough that no scaling below can overflow a float or an integer conversion.
MAX_MAGNITUDE: Final = 1e12


class BeyondLimits(UsageError):
    """A reference outside the drive's configured limits: ``not_allowed``, not ``invalid``."""


def refusal(exc: UsageError) -> CommandResult:
    """The one result of a command :func:`parse_command` refused with ``exc``."""
    outcome = Outcome.NOT_ALLOWED if isinstance(exc, BeyondLimits) else Outcome.INVALID
    return CommandResult(outcome=outcome, reason=str(exc))


def loads(text: str | bytes | bytearray) -> Any:
    """JSON text as Python values; ValueError (json.JSONDecodeError) for a duplicated key.

    NaN, Infinity and numbers too large for a float (``1e400``) are refused here too.
    """
    return json.loads(
        text, object_pairs_hook=_unique_keys, parse_constant=_no_constant, parse_float=_finite_float
    )


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise json.JSONDecodeError(f"duplicated key {key!r}", "", 0)
        out[key] = value
    return out


def _no_constant(name: str) -> Any:
    raise json.JSONDecodeError(f"{name} is not a JSON number", "", 0)


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise json.JSONDecodeError(f"{text} is beyond what a number can hold", "", 0)
    return value


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
        hz = _magnitude(payload, "frequency_hz")
        _check_limits(drive, Fraction(hz), f"{_show(hz)} Hz")
        reference_pct = hz_to_pct(hz, drive.nominal_frequency_hz)
    elif "reference_pct" in payload:
        reference_pct = _magnitude(payload, "reference_pct")
        exact = pct_to_hz(Fraction(reference_pct), Fraction(drive.nominal_frequency_hz))
        _check_limits(drive, exact, f"{_show(reference_pct)} % ({_show(float(exact))} Hz)")
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
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise UsageError(f"'{key}' must be a finite number, got {_brief(value)}")
    if isinstance(value, float) and not math.isfinite(value):
        raise UsageError(f"'{key}' must be a finite number, got {_brief(value)}")
    if abs(value) > MAX_MAGNITUDE:  # an int of 400 digits is compared, never converted
        raise UsageError(f"'{key}' is beyond ±{MAX_MAGNITUDE:g}, got {_brief(value)}")
    return float(value)


def _magnitude(payload: dict[str, Any], key: str) -> float:
    value = _number(payload, key)
    if value < 0:
        raise UsageError(
            f"'{key}' is a magnitude (≥ 0), got {_show(value)}: "
            "change the direction with forward or reverse"
        )
    return abs(value)  # -0.0 is 0


def _check_limits(drive: DrivePlan, hz: Fraction, given: str) -> None:
    """BeyondLimits when ``hz`` (exact) is outside the drive's configured range."""
    if hz > Fraction(drive.max_frequency_hz):
        raise BeyondLimits(
            f"{given} is beyond {drive.name}'s configured limit of "
            f"{_show(drive.max_frequency_hz)} Hz"
        )
    if hz and hz < Fraction(drive.min_frequency_hz):
        raise BeyondLimits(
            f"{given} is below {drive.name}'s configured minimum of "
            f"{_show(drive.min_frequency_hz)} Hz"
        )


def _show(number: float) -> str:
    """A number exactly as it reads back (shortest round trip), without a bare ".0"."""
    text = repr(float(number))
    return text[:-2] if text.endswith(".0") else text


def _brief(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:20]}…({len(text)} characters)"
