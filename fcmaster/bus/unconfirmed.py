"""The commands a line's drives have acknowledged and not yet shown in their status.

The planner's side of confirmation (:mod:`fcmaster.bus.confirm` judges; this keeps the
list): a motion command the drive acknowledged waits here, in its drive's slot and in the
line's list, until its status shows the result (``done``), the deadline passes
(``unconfirmed``), a newer motion command asks the opposite (``superseded``), or the drive
or the line is lost. Each ends exactly once, as a :class:`~fcmaster.bus.steps.Completion`.
"""

from __future__ import annotations

from fcmaster.bus.commands import Command, CommandResult, Outcome, describe
from fcmaster.bus.confirm import SHOWS_RUNNING, confirm_time, verdict
from fcmaster.bus.steps import (
    Completion,
    DriveSlot,
    Pending,
    Phase,
    Report,
    completion_of,
    result_of,
)


class Confirmations:
    """The acknowledged commands of one line that wait for their drive's status."""

    __slots__ = ("_waiting",)

    def __init__(self) -> None:
        self._waiting: list[Pending] = []

    def __len__(self) -> int:
        return len(self._waiting)

    def start(self, pending: Pending, slot: DriveSlot, now: float, report: Report) -> None:
        """``pending`` was acknowledged: wait for its drive's status to show it."""
        pending.phase = Phase.CONFIRMING
        pending.confirm_s = confirm_time(slot, pending)
        pending.confirm_by = now + pending.confirm_s
        slot.confirming.append(pending)
        self._waiting.append(pending)
        self.judge(slot, now, report)

    def judge(self, slot: DriveSlot, now: float, report: Report) -> None:
        """End the drive's commands whose result its status now shows, or cannot show."""
        for pending in list(slot.confirming):
            result = verdict(slot, pending, now)
            if result is not None:
                report.completions.append(self._end(pending, result))

    def expire(self, now: float, report: Report) -> None:
        """End the commands whose confirmation deadline has passed (checked per exchange)."""
        for pending in list(self._waiting):
            if pending.confirm_by <= now and pending.slot is not None:
                result = verdict(pending.slot, pending, now)
                if result is not None:
                    report.completions.append(self._end(pending, result))

    def replace(self, slot: DriveSlot, command: Command, report: Report) -> None:
        """A newer motion command asks the opposite of what the drive's waiting ones do."""
        wanted = SHOWS_RUNNING.get(command.action)
        if wanted is None:
            return  # references, directions and resets leave a start or stop to show itself
        for pending in list(slot.confirming):
            if SHOWS_RUNNING[pending.command.action] is not wanted:
                why = f"superseded by {describe(command)} before its status showed the result"
                report.completions.append(self._end(pending, result_of(Outcome.SUPERSEDED, why)))

    def drive_lost(self, slot: DriveSlot, report: Report) -> None:
        """``slot`` stopped answering: what waits for it ends unconfirmed."""
        why = "the drive stopped answering before its status showed the result"
        for pending in list(slot.confirming):
            report.completions.append(self._end(pending, result_of(Outcome.UNCONFIRMED, why)))

    def end_for(self, slots: list[DriveSlot], reason: str) -> list[Completion]:
        """Drives that left the line: what waits for them ends unconfirmed."""
        why = f"{reason} before the drive's status showed the result"
        waiting = [p for p in self._waiting if p.slot is not None and p.slot in slots]
        return [self._end(p, result_of(Outcome.UNCONFIRMED, why)) for p in waiting]

    def end_all(self, reason: str) -> list[Completion]:
        """The line is lost or shut: everything waiting ends unconfirmed."""
        why = f"{reason} before the drive's status showed the result"
        return [self._end(p, result_of(Outcome.UNCONFIRMED, why)) for p in list(self._waiting)]

    def _end(self, pending: Pending, result: CommandResult) -> Completion:
        assert pending.slot is not None
        pending.slot.confirming.remove(pending)
        self._waiting.remove(pending)
        pending.phase = Phase.ENDED
        return completion_of(pending, result)
