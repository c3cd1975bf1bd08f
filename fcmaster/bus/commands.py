"""Commands a caller puts to a drive, and the one result each of them gets.

The same actions and outcomes serve every surface (CLI, HTTP, MQTT, Modbus); their
names are the public ones of DESIGN.md.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any

from fcmaster.errors import (
    CommandCancelled,
    CommandError,
    CommandSuperseded,
    CommandTimedOut,
    CommandUnconfirmed,
    ControlNotAllowed,
    DriveRejected,
    UsageError,
)
from fcmaster.protocol.codec import DriveError, ParameterValue


class Action(enum.StrEnum):
    """What a command asks for."""

    START = "start"
    STOP = "stop"
    COAST = "coast"
    QUICK_STOP = "quick_stop"
    RESET = "reset"
    FORWARD = "forward"
    REVERSE = "reverse"
    JOG = "jog"
    SET_REFERENCE = "set_reference"
    READ = "read"
    WRITE = "write"

    @property
    def is_urgent(self) -> bool:
        """Stops jump the queue: they go out right after the transaction in flight."""
        return self in _URGENT

    @property
    def is_control(self) -> bool:
        """Whether the action commands the motor (needs `control: bus`)."""
        return self not in (Action.READ, Action.WRITE)


_URGENT = frozenset((Action.STOP, Action.COAST, Action.QUICK_STOP))


class Outcome(enum.StrEnum):
    """How a command ended; exactly one per command."""

    DONE = "done"
    REFUSED = "refused"  # the drive said no
    TIMEOUT = "timeout"
    NOT_ALLOWED = "not_allowed"  # monitor-only drive, or beyond the configured limits
    INVALID = "invalid"  # malformed
    CANCELLED = "cancelled"  # shutdown, line lost
    UNCONFIRMED = "unconfirmed"  # acknowledged, but the status never showed the result in time
    SUPERSEDED = "superseded"  # a newer command replaced it before it reached the wire


@dataclass(slots=True, frozen=True, kw_only=True)
class CommandResult:
    """The one result of one command."""

    outcome: Outcome
    reason: str = ""
    value: ParameterValue | None = None
    error: DriveError | None = None

    @property
    def ok(self) -> bool:
        """Whether the command was carried out."""
        return self.outcome is Outcome.DONE

    def to_json(self) -> dict[str, Any]:
        """The result as DESIGN.md's JSON: outcome, reason, and value or error."""
        out: dict[str, Any] = {"outcome": self.outcome.value, "reason": self.reason}
        if self.value is not None:
            out["value"] = self.value.value
            out["unit"] = self.value.unit
            out["raw"] = self.value.raw
        if self.error is not None:
            out["error"] = {"code": self.error.code, "text": self.error.text}
        return out

    def raise_for_outcome(self) -> CommandResult:
        """Return self when done; otherwise raise the matching CommandError."""
        match self.outcome:
            case Outcome.DONE:
                return self
            case Outcome.REFUSED:
                error = self.error or DriveError(-1, self.reason)
                raise DriveRejected(self.reason, code=error.code, text=error.text)
            case Outcome.TIMEOUT:
                raise CommandTimedOut(self.reason)
            case Outcome.NOT_ALLOWED:
                raise ControlNotAllowed(self.reason)
            case Outcome.INVALID:
                raise UsageError(self.reason)
            case Outcome.CANCELLED:
                raise CommandCancelled(self.reason)
            case Outcome.UNCONFIRMED:
                raise CommandUnconfirmed(self.reason)
            case Outcome.SUPERSEDED:
                raise CommandSuperseded(self.reason)
        raise CommandError(self.reason)  # pragma: no cover - every outcome is matched above


@dataclass(slots=True, frozen=True, kw_only=True)
class Command:
    """A validated command for one drive (or, with ``drive`` None, a line broadcast)."""

    action: Action
    reference_pct: float | None = None  # start / set_reference
    parameter: str | None = None  # read / write, the manual's notation
    index: int = 0
    value: float | str | None = None  # write
    persist: bool = False  # write to non-volatile memory too
    actor: str = ""  # who asked (token name, "cli", "mqtt:client-id"), for the log
    # The gateway's own housekeeping read (the watchdog audit): its result goes to the one
    # who asked, without an audit line or a command event. Honoured for reads only.
    internal: bool = False


def describe(command: Command) -> str:
    """The command in a few words, for a reason that names it ("set_reference 40 % by ops")."""
    words = [command.action.value]
    if command.reference_pct is not None:
        words.append(f"{command.reference_pct:g} %")
    if command.parameter is not None:
        words.append(
            command.parameter if command.index == 0 else f"{command.parameter}[{command.index}]"
        )
    if command.value is not None:
        words.append(f"= {command.value}")
    if command.actor:
        words.append(f"by {command.actor}")
    return " ".join(words)
