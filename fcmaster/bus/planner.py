"""What goes on the wire next: the pure, synchronous scheduler of one half-duplex line.

Theory of operation
-------------------
The planner owns the line's queues and each drive's bus-side state; the BusMaster asks it
for a :class:`Step`, carries the step out, and reports back with :meth:`Planner.on_reply`
or :meth:`Planner.on_failure`. Time is always an argument, so every rule here is tested
without asyncio. Order of service (DESIGN.md):

1. urgent commands (stop, coast, quick stop), oldest first;
2. other commands and parameter access, in arrival order (taking turns with the polls once
   they have held the line a while: :mod:`~fcmaster.bus.share`);
3. a probe of a demoted drive, when one is due and the probe budget allows;
4. the idle poll, round-robin over the drives that are not demoted.

Polls, probes, demotion, the probe budget and line silence are the
:class:`~fcmaster.bus.rotation.Rotation`'s. Commands are retried up to ``retries`` times,
each retry going back to the head of its queue so an urgent stop can still come in between.
Idle polls are never retried: a failed poll counts toward demotion and the round moves on,
so a drive that stops answering costs one timeout per round until it is demoted, then one
probe in its turn, within the probes' share of the line. A drive not heard from since the
line opened is not in the round: its one poll goes in the probes' share.

Choosing and doing are apart: :meth:`Planner.peek` chooses the next step and changes
nothing; :meth:`Planner.commit` makes it happen when it goes on the wire. A step chosen
inside the pause is sent only if it is :meth:`Planner.still_next` when the pause ends: a
command that came in meanwhile may go first or supersede it, and a command cancelled at
shutdown meanwhile must not go out at all. A command's lifecycle is its
:class:`~fcmaster.bus.steps.Phase`.

Control state. A ``control: bus`` drive carries its commanded :class:`ControlIntent` in
every exchange, which keeps the drive's control-word watchdog fed. Before the master knows
the drive's state it sends no command (intent None) unless ``on_start: stop``; the first
good reply is *adopted*: a running drive is commanded to keep running at its present output
and direction, a stopped one to stay stopped. A drive that returns from being demoted is
adopted again unless the last command was a stop, and so is every drive once the line has
been down (:meth:`Planner.on_line_down`), so a drive that comes back is never started by
the master on its own. A motion command (start, jog, reference, direction, reset) that
timed out may or may not have been applied, so neither it nor the previous intent is
repeated: the drive is adopted again from its next good status. Reverting would pulse the
motor (a start applied, its replies lost, then a stop). A trip (status fault rising) turns
the intent into a stop, so a later reset does not restart the motor; a new start is needed.

A drive restarting on a request (``deaf_s``: Mitsubishi's reset) or settling after one
(``settle_s``: a profile's pacing) is sent nothing until then (:mod:`~fcmaster.bus.pacing`).

Every command ends exactly once, reported as a :class:`Completion`: the master resolves
the caller's future from it. A stop supersedes motion commands of the same drive that are
still queued (they end ``superseded``); a newer reference takes the place of a queued one
(which ends ``superseded``, naming it). Neither touches a command whose step is in flight (the
last step :meth:`Planner.next_step` handed out and not yet reported back): the drive may
already be acting on it, and its reply must still find it at the head of its queue.

Its parts: the message types (:mod:`~fcmaster.bus.steps`), admission
(:mod:`~fcmaster.bus.admission`), the queue (:mod:`~fcmaster.bus.queue`), polls, probes and
liveness (:mod:`~fcmaster.bus.rotation`), the intent algebra (:mod:`~fcmaster.bus.intents`), a
command's exchanges (:mod:`~fcmaster.bus.progress`), what a reply says of its drive
(:mod:`~fcmaster.bus.hearing`), commands awaiting confirmation (:mod:`~fcmaster.bus.unconfirmed`).
Left here: choosing the next step, and what a failure means for its drive.
"""

from __future__ import annotations

import dataclasses

from fcmaster.bus import admission, pacing
from fcmaster.bus.codecs import monitor_keys
from fcmaster.bus.commands import Action, Command, CommandResult
from fcmaster.bus.hearing import Hearing
from fcmaster.bus.intents import (
    forget,
    stopping_only,
    without_reset,
)
from fcmaster.bus.plan import DrivePlan, LinePlan, OnStart
from fcmaster.bus.progress import Progress
from fcmaster.bus.queue import CommandQueue
from fcmaster.bus.rotation import Choice, Rotation
from fcmaster.bus.share import CommandShare
from fcmaster.bus.steps import (
    Completion,
    DriveSlot,
    Pending,
    Phase,
    Report,
    Step,
    StepKind,
    Transition,
)
from fcmaster.bus.unconfirmed import Confirmations
from fcmaster.protocol.codec import DriveCodec, Exchange, ParameterKey, Reply
from fcmaster.protocol.drive import ControlIntent, Motion

__all__ = [
    "Completion",
    "DriveSlot",
    "Pending",
    "Phase",
    "Planner",
    "Report",
    "Step",
    "StepKind",
    "Transition",
]


class Planner:
    """The scheduler of one line. Synchronous, deterministic, clock-free."""

    def __init__(
        self, plan: LinePlan, codec: DriveCodec, *, answered_before: frozenset[int] = frozenset()
    ) -> None:
        self.plan = plan
        self.codec = codec
        self._queue = CommandQueue()
        self.slots: list[DriveSlot] = [self._new_slot(drive) for drive in plan.drives]
        self._by_name: dict[str, DriveSlot] = {slot.name: slot for slot in self.slots}
        self.rotation = Rotation(plan, self.slots, answered_before=answered_before)
        self._in_flight: Pending | None = None  # the command whose step is on the wire
        self._confirming = Confirmations()  # acknowledged, waiting for the status to show it
        self._hearing = Hearing(codec, self.rotation, self._confirming)
        self._progress = Progress(codec, self._queue, self._confirming, self._targets)
        self._peeked: Step | None = None  # the step peek chose, until it is committed
        self._share = CommandShare()  # how long commands may keep the round waiting
        self.held = False  # nothing more is sent until the master has reconfigured the line

    def _new_slot(self, drive: DrivePlan) -> DriveSlot:
        codec = self.codec
        slot = DriveSlot(plan=drive, sequence=codec.poll_sequence(self._monitor(drive)))
        if drive.control and drive.on_start is OnStart.STOP:
            slot.intent = ControlIntent(Motion.STOP)
            # Where a poll cannot carry the stop that on_start asks for (an ENC frame holds
            # one command), the stop goes out on its own, ahead of everything.
            if not codec.poll(slot.address, slot.intent, None).carries_control:
                stop = Command(action=Action.STOP, actor="on_start")
                self._queue.add(Pending(stop, slot, []), None)
        return slot

    def _monitor(self, drive: DrivePlan) -> tuple[ParameterKey, ...]:
        return monitor_keys(self.codec, drive)

    def reconfigure(self, plan: LinePlan, reason: str) -> list[Completion]:
        """Serve the drives of ``plan`` from now on; its line settings are this line's.

        Called between exchanges. A drive kept with its address, ``control`` and
        ``on_start`` keeps its bus-side state (online, commanded intent, commands waiting),
        so it is never jolted, and takes its new plan and monitor list; any other is a new
        drive, taken over as at start. The commands of a drive that left end cancelled with
        ``reason``. The poll round goes on from where it was.
        """
        slots = []
        for drive in plan.drives:
            slot = self._by_name.get(drive.name)
            if slot is None or not _same_drive(slot.plan, drive):
                slot = self._new_slot(drive)
            elif slot.plan != drive:
                slot.plan = drive
                slot.sequence = self.codec.poll_sequence(self._monitor(drive))
                slot.cursor = 0
            slots.append(slot)
        gone = [slot for slot in self.slots if slot not in slots]
        ended = self._queue.cancel_for(gone, reason) + self._confirming.end_for(gone, reason)
        if self._in_flight is not None and self._in_flight.slot in gone:
            self._in_flight = None
        self.plan = plan
        self.slots = slots
        self._by_name = {slot.name: slot for slot in slots}
        self.rotation.reconfigure(plan, slots)
        self._peeked = None
        self.held = False
        return ended

    # -- commands in -------------------------------------------------------------------

    def slot(self, name: str) -> DriveSlot:
        """The drive called ``name``; KeyError if the line has none."""
        return self._by_name[name]

    def find(self, name: str) -> DriveSlot | None:
        """The drive called ``name``; None if the line has none (or "*", the line)."""
        return self._by_name.get(name)

    def submit(self, name: str | None, command: Command, ticket: object) -> list[Completion]:
        """Queue ``command`` for drive ``name`` (None: broadcast to the line).

        Returns the commands this submission ended at once: this one when it cannot go on
        the wire (invalid, not allowed), or queued motion commands a stop supersedes.
        """
        if (refusal := self.refusal(name, command)) is not None:
            return [Completion((ticket,), command, name or "*", refusal)]
        slot = None if name is None else self._by_name.get(name)
        # It may go before the step just peeked, or end or change the command that step
        # carries (a stop supersedes it, a newer reference takes its place): choose again.
        self._peeked = None
        return self._queue.add(Pending(command, slot, [ticket]), self._in_flight)

    def refusal(self, name: str | None, command: Command) -> CommandResult | None:
        """Why the config refuses ``command`` for drive ``name`` (None: it does not)."""
        slot = None if name is None else self._by_name.get(name)
        return admission.refusal(self.codec, self.plan.name, self.slots, name, slot, command)

    def cancel_all(self, reason: str) -> list[Completion]:
        """End every queued command as cancelled (shutdown, line lost)."""
        ended = self._queue.cancel_all(reason)
        ended.extend(self._confirming.end_all(reason))
        self._in_flight = None
        self._peeked = None
        return ended

    def cancel_queued(self, reason: str) -> list[Completion]:
        """End every queued command but the stops and the one on the wire as cancelled.

        At shutdown nothing new may go out: the stops (urgent, always safe) stay, and so
        does the command whose exchange is on the wire, which ends with what the drive says.
        """
        ended = self._queue.cancel_unsent(reason, self._in_flight)
        chosen = None if self._peeked is None else self._peeked.pending
        if chosen is not None and chosen.phase is Phase.ENDED:
            self._peeked = None  # chosen inside the pause, not sent: it must not go out now
        return ended

    def on_line_down(self) -> None:
        """The port was lost or shut: adopt each drive again when it is next heard from.

        A commanded stop is kept, as it is safe to repeat; a commanded motion is not, since
        the drive may have stopped meanwhile (its control-word timeout) and must not be
        started again by the master on its own.
        """
        for slot in self.slots:
            forget(slot)
            slot.ramps_asked = False  # read again once it answers: it may have been replaced
        self.rotation.line_down()

    @property
    def line_silent(self) -> bool:
        """Whether every drive that was answering fell silent together (a line fault)."""
        return self.rotation.silent

    @property
    def has_commands(self) -> bool:
        """Whether commands are waiting for the line."""
        return bool(self._queue)

    @property
    def confirming(self) -> int:
        """How many acknowledged commands wait for their drive's status to show the result."""
        return len(self._confirming)

    # -- what next -----------------------------------------------------------------------

    def next_step(self, now: float) -> Step | None:
        """The next exchange, committed at once (:meth:`peek` then :meth:`commit`)."""
        step = self.peek(now)
        if step is not None:
            self.commit(step, now)
        return step

    def peek(self, now: float) -> Step | None:
        """The next exchange to carry out; None: nothing to do before :meth:`next_wakeup`.

        Nothing changes until :meth:`commit`: the master peeks inside the pause after a
        reply, and when a command comes in meanwhile it peeks again instead.
        """
        pending = self._next_command(now) if self._queue else None
        choice = None
        if pending is None or self._share.poll_first(pending, now):
            choice = self.rotation.peek(now)
        step: Step | None = None
        if choice is not None:
            slot = choice.slot
            if choice.kind is StepKind.POLL:
                step = Step(StepKind.POLL, self._poll(slot), slot)
            else:
                probe = self.codec.poll(slot.address, stopping_only(slot.intent), None)
                step = Step(StepKind.PROBE, probe, slot)
        elif pending is not None:
            step = self._progress.step(pending)
        self._peeked = step
        return step

    def still_next(self, step: Step) -> bool:
        """Whether ``step``, just peeked, is still the one to send.

        Not when a command came in since (it may go first, or supersede or replace the
        command of ``step``) or the command of ``step`` ended (cancelled at shutdown): then
        peek again. A step that is not still next must never be committed.
        """
        return step is self._peeked and not self.held

    def commit(self, step: Step, now: float) -> None:
        """``step``, the one :meth:`peek` just chose, goes on the wire now."""
        if step is not self._peeked:
            raise ValueError("only the step just peeked can be committed")
        self._peeked = None
        pending, slot = step.pending, step.slot
        self._in_flight = pending
        if pending is not None:
            self._share.command_sent(now)
            command = pending.command
            if command.action.is_control and pending.intent is None:
                pending.phase = Phase.LEARNING
                return
            pending.phase = Phase.SENDING
            if command.action.is_urgent and pending.intent is not None:
                # A stop holds from the moment it is sent, even if no reply confirms it.
                for target in self._targets(slot):
                    target.intent = without_reset(pending.intent)
            return
        assert slot is not None
        self._share.after_command = False
        if step.kind is StepKind.POLL:
            if slot.urgent_reads:
                slot.urgent_reads.popleft()
            else:
                slot.cursor += 1
        self.rotation.commit(Choice(step.kind, slot), now)

    def next_wakeup(self, now: float) -> float | None:
        """When a probe falls due or a drive is heard again (None: only a command wakes us)."""
        return self.rotation.next_wakeup(now)

    def _next_command(self, now: float) -> Pending | None:
        """The oldest urgent command, else the oldest other one, whose drive can hear it."""
        return self._queue.next_ready(now, self._targets)

    def _poll(self, slot: DriveSlot) -> Exchange:
        """The drive's next poll: a condition read it owes, else its rotation's next item."""
        read: ParameterKey | None
        if slot.urgent_reads:
            read = slot.urgent_reads[0]
        else:
            read = slot.sequence[slot.cursor % len(slot.sequence)]
        return self.codec.poll(slot.address, slot.intent, read)

    def _targets(self, slot: DriveSlot | None) -> list[DriveSlot]:
        return [slot] if slot is not None else [s for s in self.slots if s.plan.control]

    # -- what came back ------------------------------------------------------------------

    def on_sent(self, step: Step, now: float) -> Report:
        """A step that expects no reply (broadcast, reset without answer) went out."""
        report = Report()
        self._in_flight = None
        if step.pending is not None:
            self._progress.advance(step.pending, report, None, now)
        if self._confirming:
            self._confirming.expire(now, report)
        pacing.leave_alone(step, self._targets, now)
        return report

    def on_reply(self, step: Step, reply: Reply, now: float) -> Report:
        """A valid reply to ``step`` arrived."""
        report = Report()
        pacing.leave_alone(step, self._targets, now)
        self._in_flight = None
        slot = step.slot
        tripped = slot is not None and self._hearing.heard(slot, step, reply, now, report)
        if step.pending is not None:
            self._progress.advance(step.pending, report, reply, now)
        if tripped and slot is not None and slot.intent is not None:
            # After the command's own intent: a trip in the reply to a start still stops.
            slot.intent = dataclasses.replace(slot.intent, motion=Motion.STOP)
        if self._confirming:
            self._confirming.expire(now, report)
        return report

    def on_failure(self, step: Step, now: float, reason: str) -> Report:
        """No valid reply to ``step`` before its deadline."""
        report = Report()
        pacing.leave_alone(step, self._targets, now)
        self._in_flight = None
        slot = step.slot
        pending = step.pending
        # A command to be retried stays at the head of its queue, and its drive's misses
        # are not counted until its retries are spent.
        retried = pending is not None and not self._progress.failed(
            pending, report, reason, self.plan.retries
        )
        if slot is not None and not retried:
            kind = None if step.kind is StepKind.COMMAND else step.kind
            # After the deadline a late reply may still be arriving: the line is not free.
            tail_s = self.plan.late_reply_s(step.exchange.reply_length)
            self.rotation.failed(slot, kind, now, tail_s, report)
            for transition in report.transitions:  # several at once when the line fell silent
                demoted = self._by_name[transition.drive.name]
                demoted.urgent_reads.clear()
                demoted.ramps_asked = False  # read again when it returns: it may be another
                forget(demoted)  # adopt again when it returns
                self._confirming.drive_lost(demoted, report)
        if self._confirming:
            self._confirming.expire(now, report)
        return report


def _same_drive(old: DrivePlan, new: DrivePlan) -> bool:
    """Whether ``new`` is ``old`` with other settings: the same station, taken over alike."""
    return (old.address, old.control, old.on_start) == (new.address, new.control, new.on_start)
