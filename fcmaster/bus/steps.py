"""What the planner and the master say to each other: the line's messages, plain data.

A :class:`Step` is one exchange to carry out and why; a :class:`Report` is what a reply or
a failure changed (commands that ended, drives that came or went, the line falling silent
or answering again). :class:`DriveSlot` is one drive's bus-side state and :class:`Pending`
one queued command, both owned by the planner and its parts.
"""

from __future__ import annotations

import enum
from collections import deque
from dataclasses import dataclass, field

from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.bus.plan import DrivePlan
from fcmaster.protocol.codec import Exchange, ParameterKey
from fcmaster.protocol.drive import ControlIntent, Motion


class StepKind(enum.Enum):
    """Why an exchange is on the wire."""

    COMMAND = "command"
    POLL = "poll"
    PROBE = "probe"


class Phase(enum.Enum):
    """Where a command is in its life; it ends exactly once."""

    QUEUED = "queued"  # waiting; nothing of it has gone out, so it may be superseded
    LEARNING = "learning"  # polling the drive's state before changing part of it
    SENDING = "sending"  # its exchanges are going out (some may have gone)
    CONFIRMING = "confirming"  # acknowledged; waiting for the status to show its result
    ENDED = "ended"  # its result is reported


@dataclass(slots=True, eq=False)
class DriveSlot:
    """The bus-side state of one drive."""

    plan: DrivePlan
    sequence: tuple[ParameterKey | None, ...]
    intent: ControlIntent | None = None  # what every exchange commands; None: nothing
    online: bool | None = None  # None until the first reply or demotion
    failures: int = 0  # consecutive
    next_probe_at: float = 0.0
    quick_probe: bool = False  # went quiet with the whole line: probed again at once
    cursor: int = 0
    urgent_reads: deque[ParameterKey] = field(default_factory=deque)
    fault: bool = False
    warning: bool = False
    running: bool | None = None  # as the last status said; None: not known yet
    reverse: bool = False
    output_hz: float | None = None  # the last output reported (a magnitude)
    deaf_until: float = 0.0  # restarting or settling (bus.pacing): nothing goes to it before
    local: bool = False  # the last status said local operation: bus commands are ignored
    status_word: int | None = None  # the last status word, raw
    alarms: dict[str, tuple[str, ...]] = field(default_factory=dict)  # source word → texts
    alarms_read: bool = False  # an alarm word was read since the fault bit last rose
    confirming: list[Pending] = field(default_factory=list)  # acknowledged, result not shown
    ramp_up_s: float | None = None  # the drive's acceleration time, once read
    ramp_down_s: float | None = None  # its deceleration time, once read
    ramps_asked: bool = False  # the ramp reads are queued for this time online
    at_reference: bool | None = None  # as the last status said; None: not known yet
    # Adoption of a drive found running off its reference: what it executes was asked
    # (FC 16-00), and once read, the stop it executes (None: motion).
    executed_asked: bool = False
    executed_known: bool = False
    executed: Motion | None = None
    # The last output read was below the one before; None: fewer than two read yet.
    output_falling: bool | None = None
    adopted: ControlIntent | None = None  # the intent adoption set, while it is the intent

    @property
    def name(self) -> str:
        """The drive's configured name."""
        return self.plan.name

    @property
    def address(self) -> int:
        """The drive's bus address."""
        return self.plan.address


@dataclass(slots=True, eq=False)
class Pending:
    """A command waiting for the line, with every ticket its result answers."""

    command: Command
    slot: DriveSlot | None  # None: a broadcast to the line
    tickets: list[object]
    phase: Phase = Phase.QUEUED
    attempts: int = 0  # failed attempts at the exchange (or access sequence) under way
    part: int = 0  # which of the command's exchanges is next
    intent: ControlIntent | None = None  # the intent this command sends, once built
    access: tuple[Exchange, ...] = ()  # a read's or write's exchanges, as last built
    learned: int = 0  # state-learning polls answered before a relative command
    confirm_by: float = 0.0  # CONFIRMING: the status must show the result by then
    confirm_s: float = 0.0  # CONFIRMING: the time it was given


@dataclass(slots=True, frozen=True)
class Step:
    """One exchange to carry out."""

    kind: StepKind
    exchange: Exchange
    slot: DriveSlot | None
    pending: Pending | None = None


@dataclass(slots=True, frozen=True)
class Completion:
    """A command that has ended: resolve every ticket with ``result``."""

    tickets: tuple[object, ...]
    command: Command
    drive: str
    result: CommandResult


@dataclass(slots=True, frozen=True)
class Transition:
    """A drive that went online or offline."""

    drive: DrivePlan
    online: bool


@dataclass(slots=True)
class Report:
    """What one reply or failure changed, for the master to pass on."""

    completions: list[Completion] = field(default_factory=list)
    transitions: list[Transition] = field(default_factory=list)
    line_silent: bool | None = None  # the line fell silent (True) or answered again (False)


def completion_of(pending: Pending, result: CommandResult) -> Completion:
    """``pending`` ended with ``result``, for every ticket it answers."""
    name = pending.slot.name if pending.slot else "*"
    return Completion(tuple(pending.tickets), pending.command, name, result)


def result_of(outcome: Outcome, reason: str) -> CommandResult:
    """A result with no value."""
    return CommandResult(outcome=outcome, reason=reason)
