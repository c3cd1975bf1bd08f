"""A command's way through its exchanges, and what each reply or failure means for it.

A command may take several exchanges (a Mitsubishi run is a frequency write and a run
command; its parameter access selects the parameter page first). They go one after the
other; a refusal of any of them ends the command with that refusal, and otherwise the last
one's reply is the command's result. A parameter access that fails part-way is retried from
its first exchange, since what the earlier ones selected in the drive may be gone. A control
command whose drive's state is not known yet first learns it (the status, then the items
the protocol reports apart from it), so that changing part of the state keeps the rest.

A control command acknowledged by its drive takes effect as the drive's commanded intent at
once (every later exchange carries it); one whose result the status must show (a start, a
stop) then waits for it in the :class:`~fcmaster.bus.unconfirmed.Confirmations`, and the
others end ``done``.
"""

from __future__ import annotations

from collections.abc import Callable

from fcmaster.bus import admission
from fcmaster.bus.adoption import not_adopted
from fcmaster.bus.commands import CommandResult, Outcome
from fcmaster.bus.confirm import LOCAL, needs_confirmation
from fcmaster.bus.intents import (
    apply,
    current,
    learning_read,
    needs_learning,
    unknown,
    without_reset,
)
from fcmaster.bus.queue import MOTION_ACTIONS, CommandQueue, superseded
from fcmaster.bus.steps import (
    DriveSlot,
    Pending,
    Phase,
    Report,
    Step,
    StepKind,
    completion_of,
    result_of,
)
from fcmaster.bus.unconfirmed import Confirmations
from fcmaster.protocol.codec import DriveCodec, Reply
from fcmaster.protocol.drive import ControlIntent

Targets = Callable[[DriveSlot | None], list[DriveSlot]]


class Progress:
    """Carries queued commands through their exchanges to their one result each."""

    def __init__(
        self,
        codec: DriveCodec,
        queue: CommandQueue,
        confirming: Confirmations,
        targets: Targets,
    ) -> None:
        self._codec = codec
        self._queue = queue
        self._confirming = confirming
        self._targets = targets  # the drives a command is for (all bus drives: broadcast)

    def step(self, pending: Pending) -> Step:
        """The exchange ``pending`` needs next."""
        codec, slot, command = self._codec, pending.slot, pending.command
        if command.action.is_control:
            if slot is not None and needs_learning(slot, pending):
                # Learn what the drive is doing before changing part of it: the status
                # first, then (for protocols that report the output apart from the status,
                # such as Mitsubishi) the items of the drive's monitor list in turn.
                exchange = codec.poll(slot.address, None, learning_read(slot, pending))
                return Step(StepKind.COMMAND, exchange, slot, pending)
            if pending.intent is None:
                base = ControlIntent() if slot is None else current(slot)
                pending.intent = apply(base, command)
            exchanges = codec.control(0 if slot is None else slot.address, pending.intent)
            exchange = exchanges[pending.part]
        else:
            assert slot is not None  # access commands always name a drive
            # Built again for each exchange: every telegram carries the drive's control word
            # as it is now, and one built before a stop was sent must not undo it.
            pending.access = admission.build_access(codec, slot, command)
            exchange = pending.access[pending.part]
        return Step(StepKind.COMMAND, exchange, slot, pending)

    def failed(self, pending: Pending, report: Report, reason: str, retries: int) -> bool:
        """No valid reply to ``pending``'s exchange; whether that ended it.

        It is retried (it stays at the head of its queue) up to ``retries`` times; then it
        ends ``timeout``. A motion command for a drive whose stop is queued ends at once,
        ``superseded``: the stop came in while it was on the wire.
        """
        pending.attempts += 1
        if pending.access:
            pending.part = 0  # again from the start: what a first exchange selected may be gone
        action = pending.command.action
        stop = self._queue.stop_for(pending.slot) if action in MOTION_ACTIONS else None
        if pending.attempts <= retries and stop is None:
            return False
        sent = pending.phase is Phase.SENDING
        if stop is not None:
            # A stop came in while this was on the wire: retried, it would follow the stop.
            self.finish(pending, report, superseded(pending, stop))
        else:
            self.finish(pending, report, result_of(Outcome.TIMEOUT, reason))
        if sent and action.is_control and not action.is_urgent:
            # The drive may or may not have applied it: adopt it again from its next good
            # status. A stop that timed out is kept (it holds from being sent).
            for target in self._targets(pending.slot):
                unknown(target)
        return True

    def advance(self, pending: Pending, report: Report, reply: Reply | None, now: float) -> None:
        """``pending``'s exchange was answered by ``reply`` (None: it expects no answer)."""
        command = pending.command
        if reply is not None and reply.error is not None:
            self.finish(
                pending,
                report,
                CommandResult(
                    outcome=Outcome.REFUSED,
                    error=reply.error,
                    reason=f"the drive refused: {reply.error.text} (error {reply.error.code})",
                ),
            )
            return
        if not command.action.is_control:
            pending.part += 1
            if pending.part < len(pending.access):
                # attempts are not reset: a failure starts the access over from its first
                # exchange, so the command's retries must bound the whole sequence
                return
            value = None if reply is None else reply.value
            self.finish(pending, report, CommandResult(outcome=Outcome.DONE, value=value))
            return
        slot = pending.slot
        if pending.phase is Phase.LEARNING:
            pending.attempts = 0  # that was a state-learning poll; now the command
            pending.learned += 1
            unlearned = slot is not None and slot.intent is None
            if unlearned and slot is not None and pending.learned > len(slot.sequence) + 1:
                # A whole rotation answered and still not adoptable: do not poll forever.
                reason = f"{slot.name}'s state could not be learned ({not_adopted(slot)})"
                self.finish(pending, report, result_of(Outcome.TIMEOUT, reason))
            return
        assert pending.intent is not None  # built when the command's own exchange went
        pending.part += 1
        total = len(self._codec.control(0 if slot is None else slot.address, pending.intent))
        if pending.part < total:
            pending.attempts = 0
            return
        for target in self._targets(slot):
            target.intent = without_reset(pending.intent)
            self._confirming.replace(target, command, report)
        confirm = needs_confirmation(pending)
        if reply is not None and reply.status and not reply.status.accepts_bus_control:
            outcome = Outcome.UNCONFIRMED if confirm else Outcome.REFUSED
            self.finish(pending, report, result_of(outcome, LOCAL))
        elif not confirm or slot is None:
            self.finish(pending, report, result_of(Outcome.DONE, ""))
        else:
            self._queue.remove(pending)
            self._confirming.start(pending, slot, now, report)

    def finish(self, pending: Pending, report: Report, result: CommandResult) -> None:
        """End ``pending`` with ``result``."""
        # Usually the head of its queue; a command behind one for a restarting drive may
        # have been served first.
        self._queue.remove(pending)
        report.completions.append(completion_of(pending, result))
