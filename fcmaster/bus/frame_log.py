"""A line's recent frames with their times, for captures (``fcmaster capture``).

The link appends one tuple per frame it writes or reads and nothing more, so keeping the
log costs the bus nothing it would notice; the reading side (an HTTP request now and then)
does the work of numbering and slicing. Each frame carries a sequence number, so a client
that follows the log with ``since`` gets every frame once, in order, and learns how many
it missed when it fell more than the ring's length behind.
"""

from __future__ import annotations

import itertools
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

FRAME_LOG_LENGTH: Final = 4096  # frames kept per line: a few seconds of a busy line
TX: Final = "tx"  # master → drives
RX: Final = "rx"  # drives → master (every frame the framer cut, answer or not)

# (sequence number, direction, monotonic time, wall-clock time, bytes)
FrameRecord = tuple[int, str, float, float, bytes]


@dataclass(slots=True, frozen=True)
class FramesSince:
    """What a follower gets: the frames after its last one, and how many it missed."""

    frames: list[FrameRecord]
    next: int  # the ``since`` to ask with next time
    missed: int  # frames that left the ring before they were asked for


class FrameLog:
    """A bounded ring of the last frames on one line, oldest first."""

    def __init__(self, wall: Callable[[], float], length: int = FRAME_LOG_LENGTH) -> None:
        """Keep the last ``length`` frames, each also stamped with ``wall()`` (Unix time)."""
        self._wall = wall  # the line's clock's wall(): time.time itself on the real clock
        self._ring: deque[FrameRecord] = deque(maxlen=length)
        self._seq = itertools.count()

    def add(self, direction: str, data: bytes, at: float) -> None:
        """Record ``data`` sent or received at monotonic time ``at``."""
        self._ring.append((next(self._seq), direction, at, self._wall(), data))

    def since(self, seq: int = 0) -> FramesSince:
        """The frames numbered ``seq`` and after that are still in the ring."""
        ring = list(self._ring)  # a copy: the ring may move on while the caller reads
        if not ring:
            return FramesSince([], 0, 0)
        first, last = ring[0][0], ring[-1][0]
        seq = max(seq, 0)
        if seq > last + 1:  # numbers from before the daemon restarted: start afresh
            seq = first
        missed = max(0, first - seq)
        start = max(seq, first) - first
        return FramesSince(ring[start:], last + 1, missed)
