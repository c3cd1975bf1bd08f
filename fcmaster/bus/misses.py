"""Many drives missing their polls in a row: after one round, the others go in between.

Round-robin alone serves a line badly when many drives stop answering at once (a cabinet's
supply switched off, a feeder tripped, a restart that finds part of the plant unpowered):
the drives still answering wait behind every silent one's reply deadline, each missed
``offline_after`` times. 110 of 126 drives losing power left the 16 others unanswered for
6 s at 19200 baud with the default deadlines and 13 s with ``timeout_s: 0.1``, three rounds
over (``benchmarks/mass_loss.py``).

So once the polls missed since the line last answered have taken ``STREAK_AFTER_S`` (more
than a lost reply or two at the deadlines the line measures) and until every drive is
answering again or given up (a **miss streak**), the rotation chooses differently. A drive
is *confirmed* once it answers during the streak. First every drive not confirmed is
*tried* once, the one heard longest ago first (the round's own order, the misses that began
the streak counting as tries): nothing tells a drive still on from a silent one until it is
asked, and the one heard longest ago is the nearest to its control-word timeout, so no
drive still on waits longer than round-robin would have made it. A try that is answered is
followed by the next try at once. From then on the drives that missed are tried again, the
one tried longest ago first, and after each such miss the confirmed drives are polled,
round-robin, for as long as the miss took (``MISS_SHARE``: the misses take at most half the
line while drives answer), each once at most. So the drives still answering wait behind one
round of misses, not ``offline_after`` rounds, and the silent ones still reach their
``offline_after`` misses each, in the time of about five rounds of misses instead of three.
The streak ends when no drive is left to try.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from fcmaster.bus.steps import DriveSlot

MISS_SHARE = 0.5  # the most of the line's time misses take in a streak while others answer
# A streak begins once the polls missed since the line last answered took this long: until
# then round-robin costs the drives still answering no more than a lost reply or two would.
STREAK_AFTER_S = 0.2


class Misses:
    """The miss streak of one line: which drive to poll while it lasts."""

    def __init__(self) -> None:
        self.heard_at: dict[int, float] = {}  # by id(slot): when each drive last answered
        self._since: float | None = None  # when the streak began (None: no streak)
        self._owed_until = -math.inf  # confirmed drives are polled until then, after a miss
        self._next_confirmed = 0  # where the round of the confirmed drives goes on
        self._tried: dict[int, float] = {}  # by id(slot): when tried in this streak
        self._tries: dict[int, int] = {}  # by id(slot): how often tried in this streak
        self._missed_s = 0.0  # line time the misses since the line last answered took
        self._passed: set[int] = set()  # confirmed drives polled since the last miss

    @property
    def active(self) -> bool:
        """Whether a streak is on (:meth:`choose` decides the polls)."""
        return self._since is not None

    def heard(self, slot: DriveSlot, now: float) -> None:
        """``slot`` answered at ``now``."""
        self.heard_at[id(slot)] = now
        if self._since is None:  # the misses before it do not add up to a streak
            self._missed_s = 0.0
            self._tried.clear()
            self._tries.clear()

    def missed(self, slot: DriveSlot, now: float, cost_s: float) -> None:
        """``slot``, polled as answering, missed at ``now``, having cost the line ``cost_s``."""
        if self._since is None:
            # Before a streak the round chose it: its try in the streak to come.
            self._tried[id(slot)] = now
            self._tries[id(slot)] = 1
            self._missed_s += cost_s
            if self._missed_s >= STREAK_AFTER_S:
                self._since = now
            return
        if self._tries.get(id(slot), 0) < 2:
            return  # the first pass: every drive not heard since is tried, oldest first
        self._owed_until = now + cost_s * (1.0 - MISS_SHARE) / MISS_SHARE
        self._passed.clear()

    def choose(
        self, slots: list[DriveSlot], now: float, pollable: Callable[[DriveSlot], bool]
    ) -> DriveSlot | None:
        """The drive to poll next in the streak; None ends it (no drive is left to try)."""
        count = len(slots)
        if now < self._owed_until:
            for offset in range(count):
                slot = slots[(self._next_confirmed + offset) % count]
                if pollable(slot) and self._confirmed(slot) and id(slot) not in self._passed:
                    return slot
        best: DriveSlot | None = None
        best_key = (math.inf, math.inf)
        tried, heard_at = self._tried, self.heard_at
        for slot in slots:  # in the round's order: ties go to the first
            if not pollable(slot) or self._confirmed(slot):
                continue
            # Not tried in this streak yet, the one heard longest ago first (the round's
            # order); then the one tried longest ago.
            key = (tried.get(id(slot), -math.inf), heard_at.get(id(slot), -math.inf))
            if key < best_key:
                best, best_key = slot, key
        if best is None:
            # Peeking should change nothing, but ending here is safe: no drive is left to try,
            # and the round takes over; a drive that becomes pollable later (one restarting
            # after a reset, a demoted one found again) is served by the round, as before.
            self.end()
        return best

    def chosen(self, slot: DriveSlot, index: int, count: int, now: float) -> None:
        """``slot`` (at ``index`` of ``count``), which :meth:`choose` gave, is polled at ``now``."""
        self._passed.add(id(slot))  # a try that is answered has had its turn too
        if self._confirmed(slot):
            self._next_confirmed = (index + 1) % count
        else:
            self._tried[id(slot)] = now
            self._tries[id(slot)] = self._tries.get(id(slot), 0) + 1

    def end(self) -> None:
        """No streak (it ran out, or the line closed or changed)."""
        self._since = None
        self._missed_s = 0.0
        self._owed_until = -math.inf
        self._tried.clear()
        self._tries.clear()
        self._passed.clear()

    def forget(self, kept: set[int]) -> None:
        """Only the drives (by id) in ``kept`` are on the line now (a reload).

        A streak goes on: what it knows of the drives kept still holds, and ending it would
        cost the drives still answering a second round of misses. A drive the reload adds
        gets its one attempt in the probes' share, as at the line's opening (rotation).
        """
        self.heard_at = {i: at for i, at in self.heard_at.items() if i in kept}
        self._tried = {i: at for i, at in self._tried.items() if i in kept}
        self._tries = {i: n for i, n in self._tries.items() if i in kept}
        self._passed &= kept
        self._next_confirmed = 0  # the drives' places in the round may have changed

    def _confirmed(self, slot: DriveSlot) -> bool:
        since = self._since
        return since is not None and self.heard_at.get(id(slot), -math.inf) >= since
