"""The audit of ended commands: one ``command.completed`` line per command, on every surface.

A command ends once: on a line (acknowledged, refused by the drive, timed out, cancelled;
:mod:`~fcmaster.bus.reporting`), or before it reaches one (malformed, beyond the drive's
configured limits, no such drive, the daemon shutting down). Every one of them is told by
:func:`audit` with the same fields: who asked (actor), the drive, the action, the values it
carried, the outcome and the reason, so that a refused command reads like any other.

The values of a command that was parsed come from the :class:`Command` (the reference in %
and in Hz); those of one refused before it could be parsed are the payload's own, as given
(:func:`payload_values`), cut short where they are long, so a log line stays a line.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Final

from fcmaster.bus.commands import Command, CommandResult
from fcmaster.protocol.drive import pct_to_hz

EVENT: Final = "command.completed"
# The keys of a command payload that carry its values (DESIGN.md "Commands").
VALUE_KEYS: Final = ("frequency_hz", "reference_pct", "parameter", "index", "value", "persist")
_LONGEST: Final = 64  # characters of a value as given, in a refusal's audit line


def audit(
    log: Any,
    *,
    actor: str,
    drive: str,
    action: object,
    values: Mapping[str, object],
    result: CommandResult,
    **context: object,
) -> None:
    """Log the one audit line of a command that ended with ``result``."""
    log.info(
        EVENT,
        actor=actor or "-",
        drive=drive,
        command=action if isinstance(action, str) and action else "-",
        **values,
        outcome=result.outcome.value,
        reason=result.reason or None,
        **context,
    )


def command_values(
    command: Command, nominal_hz: float | None, result: CommandResult | None = None
) -> dict[str, object]:
    """The values ``command`` carried (and a read returned), for its audit line."""
    values: dict[str, object] = {}
    if command.reference_pct is not None:
        values["reference_pct"] = command.reference_pct
        if nominal_hz is not None:
            values["frequency_hz"] = round(pct_to_hz(command.reference_pct, nominal_hz), 6)
    if command.parameter is not None:
        values["parameter"] = command.parameter
        if command.index:
            values["index"] = command.index
    if command.value is not None:
        values["value"] = command.value
    if result is not None and result.value is not None:
        values["read_value"] = result.value.value
    return values


def payload_values(payload: object) -> dict[str, object]:
    """The values a command payload carried, as given (it may be refused for them)."""
    if not isinstance(payload, Mapping):
        return {}
    return {key: _as_given(payload[key]) for key in VALUE_KEYS if key in payload}


def _as_given(value: object) -> object:
    if value is None or isinstance(value, bool | int | float):
        return value
    text = value if isinstance(value, str) else repr(value)
    return text if len(text) <= _LONGEST else text[: _LONGEST - 1] + "…"
