"""Bus reads that viewers trigger, spaced out per line so they never crowd out the poll.

A parameter read by a viewer (or an anonymous loopback reader) costs a transaction on the
line the drive hangs on, taken from the poll that keeps every drive's state fresh. So each
line serves such reads one at a time, at most one every :data:`VIEWER_READ_GAP_S`; callers
beyond that wait their turn in order, and beyond :data:`MAX_WAITING` per line they are told
to come back later (:class:`ReadsBusy`, a 429) instead of queueing without bound. Operators'
reads are not limited: they are the people the fleet answers to.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Final

from fcmaster.clock import Clock
from fcmaster.errors import FcmasterError

VIEWER_READ_GAP_S: Final = 0.5  # at most 2 viewer reads a second per line
MAX_WAITING: Final = 32


class ReadsBusy(FcmasterError):
    """Too many viewer reads are already waiting on this line."""


class ViewerReads:
    """Per line: one viewer read at a time, one every ``gap_s``, ``max_waiting`` in line."""

    def __init__(
        self, clock: Clock, gap_s: float = VIEWER_READ_GAP_S, max_waiting: int = MAX_WAITING
    ) -> None:
        self.clock = clock
        self.gap_s = gap_s
        self.max_waiting = max_waiting
        self._turns: dict[str, asyncio.Lock] = {}
        self._waiting: dict[str, int] = {}
        self._next_at: dict[str, float] = {}

    @asynccontextmanager
    async def turn(self, line: str) -> AsyncIterator[None]:
        """Wait for this line's next viewer read; ReadsBusy when too many already wait."""
        if self._waiting.get(line, 0) >= self.max_waiting:
            raise ReadsBusy(f"{self.max_waiting} viewer reads already wait on {line}")
        lock = self._turns.setdefault(line, asyncio.Lock())
        clock = self.clock
        self._waiting[line] = self._waiting.get(line, 0) + 1
        try:
            await lock.acquire()
        finally:
            self._waiting[line] -= 1
        try:
            next_at = self._next_at.get(line)
            if next_at is not None:
                await clock.sleep_until(next_at)
            yield
        finally:
            self._next_at[line] = clock.now() + self.gap_s
            lock.release()
