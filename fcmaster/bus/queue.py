"""Queue discipline: which command goes next, and how commands replace one another.

Urgent commands (stop, coast, quick stop) go before all others, oldest first; the rest in
arrival order. A command for a restarting drive waits without holding up the others. A
stop supersedes the queued motion commands of its drive (they end ``superseded``, naming
the stop), including one whose attempt got no answer and waits for its retry, and the one
on the wire when its attempt then fails (see :meth:`CommandQueue.stop_for`): a retried start
must never follow a stop (start, stop, start on the wire). A newer reference takes
the place of a queued one that has not gone out (the older ends ``superseded``, naming the
newer). Neither touches the command in flight: the drive may already be acting on it, and
its reply must still find it queued.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome, describe
from fcmaster.bus.steps import Completion, DriveSlot, Pending, Phase, completion_of, result_of

MOTION_ACTIONS = frozenset(
    (Action.START, Action.JOG, Action.FORWARD, Action.REVERSE, Action.SET_REFERENCE)
)
# A command in these phases has sent nothing of its own: a stop may supersede it, a newer
# reference may replace it.
UNSENT = frozenset((Phase.QUEUED, Phase.LEARNING))


class CommandQueue:
    """The line's queued commands, urgent ones apart."""

    def __init__(self) -> None:
        self._urgent: deque[Pending] = deque()
        self._normal: deque[Pending] = deque()

    def __bool__(self) -> bool:
        return bool(self._urgent or self._normal)

    def add(self, pending: Pending, in_flight: Pending | None) -> list[Completion]:
        """Queue ``pending``; the commands that ends at once (motion a stop supersedes)."""
        command = pending.command
        if command.action.is_urgent:
            self._urgent.append(pending)
            return self._supersede(pending.slot, command, in_flight)
        if command.action is Action.SET_REFERENCE:
            replaced = self._coalesce(pending, in_flight)
            if replaced is not None:
                return [replaced]
        self._normal.append(pending)
        return []

    def next_ready(
        self, now: float, targets: Callable[[DriveSlot | None], Iterable[DriveSlot]]
    ) -> Pending | None:
        """The oldest urgent command, else the oldest other one, whose drives can hear it."""
        for queue in (self._urgent, self._normal):
            for pending in queue:
                if all(target.deaf_until <= now for target in targets(pending.slot)):
                    return pending
        return None

    def remove(self, pending: Pending) -> None:
        """``pending`` has ended: it leaves its queue (usually from the head)."""
        for queue in (self._urgent, self._normal):
            if pending in queue:
                queue.remove(pending)
                pending.phase = Phase.ENDED
                return
        raise AssertionError("finished a command that was not queued")  # pragma: no cover

    def cancel_all(self, reason: str) -> list[Completion]:
        """End every queued command as cancelled."""
        result = result_of(Outcome.CANCELLED, reason)
        ended = [completion_of(p, result) for p in (*self._urgent, *self._normal)]
        for pending in (*self._urgent, *self._normal):
            pending.phase = Phase.ENDED
        self._urgent.clear()
        self._normal.clear()
        return ended

    def cancel_for(self, slots: list[DriveSlot], reason: str) -> list[Completion]:
        """End the queued commands of ``slots`` (drives that left the line) as cancelled."""
        result = result_of(Outcome.CANCELLED, reason)
        ended: list[Completion] = []
        for queue in (self._urgent, self._normal):
            for pending in [p for p in queue if p.slot is not None and p.slot in slots]:
                queue.remove(pending)
                pending.phase = Phase.ENDED
                ended.append(completion_of(pending, result))
        return ended

    def cancel_unsent(self, reason: str, in_flight: Pending | None) -> list[Completion]:
        """End every queued non-urgent command but the one on the wire as cancelled."""
        result = result_of(Outcome.CANCELLED, reason)
        ended = [completion_of(p, result) for p in self._normal if p is not in_flight]
        for pending in self._normal:
            if pending is not in_flight:
                pending.phase = Phase.ENDED
        self._normal = deque(p for p in self._normal if p is in_flight)
        return ended

    def _supersede(
        self, slot: DriveSlot | None, command: Command, in_flight: Pending | None
    ) -> list[Completion]:
        """A stop makes queued motion commands for the same drive moot.

        Only the command on the wire is left to finish. One whose attempt got no answer
        (the drive may have applied it) ends too rather than being retried after the stop;
        its reason says it may have been seen.
        """
        ended: list[Completion] = []
        keep: deque[Pending] = deque()
        for pending in self._normal:
            if (
                pending.command.action in MOTION_ACTIONS
                and pending is not in_flight
                and (slot is None or pending.slot is slot or pending.slot is None)
            ):
                pending.phase = Phase.ENDED
                ended.append(completion_of(pending, superseded(pending, command)))
            else:
                keep.append(pending)
        self._normal = keep
        return ended

    def stop_for(self, slot: DriveSlot | None) -> Command | None:
        """The oldest stop (any urgent command) queued for ``slot``'s drive or for all."""
        for pending in self._urgent:
            if slot is None or pending.slot is slot or pending.slot is None:
                return pending.command
        return None

    def _coalesce(self, pending: Pending, in_flight: Pending | None) -> Completion | None:
        """Put ``pending`` in the place of a queued reference; that one ends superseded.

        Only the newest queued command that sets this drive's reference, so that a start
        with a reference queued in between cannot end up overriding the newest one; and only
        while its telegram is not built yet (not on the wire, not half sent).
        """
        for queued in reversed(self._normal):
            if queued.slot is not pending.slot or queued.command.reference_pct is None:
                continue
            if (
                queued.command.action is Action.SET_REFERENCE
                and queued.phase in UNSENT
                and queued.attempts == 0
                and queued is not in_flight
            ):
                result = result_of(Outcome.SUPERSEDED, f"superseded by {describe(pending.command)}")
                replaced = completion_of(queued, result)
                queued.command = pending.command
                queued.tickets = pending.tickets
                queued.intent = None  # made from the older reference if it was peeked
                return replaced
            return None
        return None


def superseded(pending: Pending, stop: Command) -> CommandResult:
    """How a motion command ``stop`` made moot ends, saying whether the drive may have seen it."""
    reason = f"superseded by {describe(stop)}"
    if pending.attempts or pending.part:
        reason += " (part of it went out unanswered: the drive may have seen it)"
    return result_of(Outcome.SUPERSEDED, reason)
