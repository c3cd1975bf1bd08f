"""Which drive the line serves when no command waits, and which drives count as present.

Polls go round-robin over the drives that answer. A drive that has not answered since the
line opened (at start, or one that was not answering when the port was lost) is not polled
as if it were there: it gets one attempt, its ordinary poll sent in the probes' share of the
line, so the drives that answer keep their poll rate while the absent ones are tried one by
one, and if it does not answer it is demoted at once. ``offline_after`` counts the misses of
drives that answered before: since the line opened, before the port was lost, or when the
daemon last ran (``answered_before``, the record kept across restarts, so that a restart
with part of the plant unpowered polls the drives that were answering at once, wherever
their addresses sit among the absent ones). One lost reply does not give up a drive that was
there. While nothing on the line has answered yet, the drives not heard from are tried in
turn, each up to ``offline_after`` times, as there is nothing better to do. A demoted drive
is only probed. Probes are held to a budget: they take at most ``probe_share`` of the line's
time while there are drives to poll, one at a time, the longest-waiting first, so many
absent drives never fall due together and starve the present ones. Each absent drive still
gets its probe, at the latest after every other absent drive has had one
(:func:`probe_period_s`). With nothing to poll (every drive absent) the budget does not
apply: the line has nothing better to do. Only unanswered probes count against the budget:
an answered one served a drive that is there, so at start the present drives are found one
after the other at once.

When many drives that answered stop at once (a cabinet's supply), each is tried once in the
round's order and from then on the drives still answering are polled between their misses
until each has answered or been given up (:mod:`~fcmaster.bus.misses`), so they wait behind
one round of misses, not ``offline_after`` rounds.

When every drive that was answering falls silent together, it is the line (a cable, the
adapter, the power) rather than the drives: they are reported offline but probed one after
the other at once, not at the slow probe interval, and as soon as anything answers the
rest are probed straight away, so the whole line is back within about one poll round.

:meth:`Rotation.peek` chooses without changing anything; :meth:`Rotation.commit` makes the
choice happen. The master peeks before the pause after a reply, and a command that comes in
during the pause goes first with nothing to undo.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fcmaster.bus.misses import Misses
from fcmaster.bus.plan import LinePlan
from fcmaster.bus.steps import DriveSlot, Report, StepKind, Transition


@dataclass(slots=True, frozen=True)
class Choice:
    """A poll or a probe, chosen and not yet made."""

    kind: StepKind
    slot: DriveSlot


def probe_period_s(plan: LinePlan, absent: int, probe_s: float) -> float:
    """The longest wait between two probes of an absent drive, with ``absent`` drives absent.

    ``probe_s`` is what one unanswered probe costs the line.
    """
    return max(plan.probe_interval_s, absent * probe_s / plan.probe_share)


class Rotation:
    """Poll rotation, demotion, the probe budget and line silence for one line's drives."""

    def __init__(
        self,
        plan: LinePlan,
        slots: list[DriveSlot],
        *,
        answered_before: frozenset[int] = frozenset(),
    ) -> None:
        """Rotation over ``slots``.

        ``answered_before``: the addresses answering when the daemon last ran, polled as
        present from the start (see the module docstring).
        """
        self.plan = plan
        self.slots = slots
        self._index = {id(slot): i for i, slot in enumerate(slots)}
        self._next_poll = 0
        self._demoted: list[DriveSlot] = []
        before = {id(s) for s in slots if s.address in answered_before}
        # Not answered since the line opened, not demoted: tried in this order, as probes are.
        self._untried: dict[int, DriveSlot] = {
            id(s): s for s in slots if s.online is None and id(s) not in before
        }
        self._heard = False  # some drive answered since the line opened
        self._quick = 0  # demoted drives with quick_probe set
        self._probe_ready_at = -math.inf  # no budgeted probe before this
        self._probe_started = 0.0
        self._probe_budgeted = False
        self._streak: set[int] = set()  # drives (by id) that failed since the line last answered
        # Answering when the port was lost, or when the daemon last ran.
        self._answered_before_down: set[int] = before
        self.silent = False  # the whole line fell silent
        self._misses = Misses()  # misses in a row: the drives still answering go between
        self._poll_started = 0.0

    def reconfigure(self, plan: LinePlan, slots: list[DriveSlot]) -> None:
        """The line's drives are now ``slots``: the round goes on at the drive due next."""
        count = len(self.slots)
        upcoming = self.slots[self._next_poll % count] if count else None
        kept = {id(slot) for slot in slots}
        before = {id(slot) for slot in self.slots}
        # A drive the reload adds is not heard yet: its one attempt in the probes' share, as
        # at the line's opening, not polls as if present.
        self._untried = {i: slot for i, slot in self._untried.items() if i in kept}
        self._untried.update(
            (id(slot), slot) for slot in slots if id(slot) not in before and slot.online is None
        )
        self.plan = plan
        self.slots = slots
        self._index = {id(slot): i for i, slot in enumerate(slots)}
        self._next_poll = 0
        if upcoming is not None and id(upcoming) in kept:
            self._next_poll = self._index[id(upcoming)]
        self._demoted = [slot for slot in self._demoted if id(slot) in kept]
        self._quick = sum(slot.quick_probe for slot in self._demoted)
        self._streak &= kept
        self._answered_before_down &= kept
        self._misses.forget(kept)

    # -- choosing ------------------------------------------------------------------------

    def peek(self, now: float) -> Choice | None:
        """The poll or probe due now, if any; nothing changes until :meth:`commit`."""
        slots, untried = self.slots, self._untried
        count = len(slots)
        poll = None
        if self._misses.active:
            poll = self._misses.choose(slots, now, lambda slot: self._pollable(slot, now))
        if poll is None:  # the round: _pollable written out, as it runs every transaction
            for offset in range(count):
                slot = slots[(self._next_poll + offset) % count]
                if slot.online is not False and slot.deaf_until <= now and id(slot) not in untried:
                    poll = slot
                    break
        if (self._demoted or untried) and (
            poll is None or self._quick or now >= self._probe_ready_at
        ):
            probe = self._due_probe(now, budgeted=poll is not None)
            if probe is not None:
                kind = StepKind.POLL if id(probe) in untried else StepKind.PROBE
                return Choice(kind, probe)
        return None if poll is None else Choice(StepKind.POLL, poll)

    def _due_probe(self, now: float, *, budgeted: bool) -> DriveSlot | None:
        """The drive to probe now: quick ones, then untried ones, then the longest waiting."""
        if not self._quick and (not budgeted or now >= self._probe_ready_at):
            for slot in self._untried.values():  # in the line's order
                if slot.deaf_until <= now:
                    return slot
        best: DriveSlot | None = None
        for slot in self._demoted:
            if slot.next_probe_at > now or slot.deaf_until > now:
                continue
            if budgeted and not slot.quick_probe and now < self._probe_ready_at:
                continue
            if best is None or (not slot.quick_probe, slot.next_probe_at) < (
                not best.quick_probe,
                best.next_probe_at,
            ):
                best = slot
        return best

    def commit(self, choice: Choice, now: float) -> None:
        """The chosen poll or probe goes on the wire now."""
        slot = choice.slot
        if id(slot) in self._untried:  # its one attempt, in the probes' share
            self._probe_started = now
            self._probe_budgeted = True
            return
        if choice.kind is StepKind.POLL:
            self._poll_started = now
            if self._misses.active:  # the round goes on where it was once the streak ends
                self._misses.chosen(slot, self._index[id(slot)], len(self.slots), now)
            else:
                self._next_poll = (self._index[id(slot)] + 1) % len(self.slots)
            return
        self._probe_started = now
        self._probe_budgeted = not slot.quick_probe
        # A quick probe goes to the back of the quick ones; others wait their interval.
        slot.next_probe_at = now if slot.quick_probe else now + self.plan.probe_interval_s

    def next_wakeup(self, now: float) -> float | None:
        """When a probe falls due or a drive is heard again, if nothing else is to do."""
        due = [
            max(s.next_probe_at, s.deaf_until) if s.online is False else s.deaf_until
            for s in self.slots
            if s.online is False or s.deaf_until > now
        ]
        return min(due) if due else None

    # -- what happened -------------------------------------------------------------------

    def heard(self, slot: DriveSlot, kind: StepKind | None, now: float, report: Report) -> None:
        """``slot`` answered (``kind``: the step's, None for a command's)."""
        slot.failures = 0
        self._misses.heard(slot, now)
        self._heard = True
        self._streak.clear()
        self._answered_before_down.clear()
        tried = self._untried.pop(id(slot), None) is not None and kind is not None
        if kind is StepKind.PROBE or tried:
            # It served a drive that is there: not charged to the probes' share.
            self._probe_budgeted = False
        if self.silent:
            self.silent = False
            report.line_silent = False
            for other in self._demoted:
                if other.quick_probe:
                    other.next_probe_at = now  # the line is back: ask each of them at once
        if slot.online is not True:
            if slot.online is False:
                self._undemote(slot)
            slot.online = True
            report.transitions.append(Transition(slot.plan, online=True))

    def failed(
        self, slot: DriveSlot, kind: StepKind | None, now: float, tail_s: float, report: Report
    ) -> None:
        """``slot`` did not answer; ``tail_s``: the line time still to pass (a late reply)."""
        slot.failures += 1
        self._streak.add(id(slot))
        if self._untried.pop(id(slot), None) is not None:
            if kind is not None:
                self._probe_ended(now, tail_s)
            if not self._heard and slot.failures < self.plan.offline_after:
                self._untried[id(slot)] = slot  # nothing answers yet: the others' turn first
                return
            # Not answered since the line opened, and tried: absent until a probe finds it.
            self._demote(slot, now, report, quick=False)
            return
        if kind is StepKind.PROBE:
            self._probe_ended(now, tail_s)
            if slot.quick_probe and not self.silent:
                # Asked again once the line was back, and still silent: a drive of its own.
                slot.quick_probe = False
                self._quick -= 1
                slot.next_probe_at = now + self.plan.probe_interval_s
            return
        if kind is StepKind.POLL and slot.online is not False:
            self._misses.missed(slot, now, now - self._poll_started + tail_s)
        if slot.online is False or slot.failures < self.plan.offline_after:
            return
        # The drives that answered; right after a reopen, those that answered before it.
        answering = [s for s in self.slots if s.online is True] or [
            s for s in self.slots if s.online is None and id(s) in self._answered_before_down
        ]
        if (
            slot in answering
            and len(answering) >= 2
            and all(id(s) in self._streak for s in answering)
        ):
            # Everything that answered went quiet together: the line, not the drives.
            self.silent = True
            report.line_silent = True
            for other in answering:
                self._demote(other, now, report, quick=True)
            return
        self._demote(slot, now, report, quick=False)

    def line_down(self) -> None:
        """The port is gone: a line silence ends with it (every drive is adopted anew).

        Called before the drives lose their online state. If the reopened line is silent,
        the drives that answered before are taken for a silent line, not demoted one by one.
        """
        self.silent = False
        self._heard = False
        self._streak.clear()
        self._misses.end()
        # Kept over reopens with no answer between them: they still answered before.
        self._answered_before_down.update(id(s) for s in self.slots if s.online is True)
        for slot in self._demoted:
            slot.quick_probe = False
        self._quick = 0

    def _pollable(self, slot: DriveSlot, now: float) -> bool:
        """Whether ``slot`` is polled as present now (not demoted, not untried, not deaf)."""
        return slot.online is not False and slot.deaf_until <= now and id(slot) not in self._untried

    def _probe_ended(self, now: float, tail_s: float) -> None:
        if self._probe_budgeted:
            # Start to start, a probe's cost is probe_share of the line's time.
            cost = now - self._probe_started + tail_s
            self._probe_ready_at = self._probe_started + cost / self.plan.probe_share
            self._probe_budgeted = False

    def _demote(self, slot: DriveSlot, now: float, report: Report, *, quick: bool) -> None:
        slot.online = False
        slot.quick_probe = quick
        self._quick += quick
        slot.next_probe_at = now if quick else now + self.plan.probe_interval_s
        self._demoted.append(slot)
        report.transitions.append(Transition(slot.plan, online=False))

    def _undemote(self, slot: DriveSlot) -> None:
        self._demoted.remove(slot)
        if slot.quick_probe:
            slot.quick_probe = False
            self._quick -= 1
