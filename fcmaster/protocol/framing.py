"""What every vendor's framer hands out: checked frames and skipped bytes.

A framer is fed arbitrary chunks of the byte stream and cuts out whole frames whose
checksum and length are right. Everything else comes back as :class:`Skipped` pieces with
a reason, so the bus can count noise and checksum errors instead of losing them. Frames and
skipped pieces together cover every byte fed, in order, exactly once.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Protocol


class SkipReason(enum.StrEnum):
    """Why bytes were not part of a frame."""

    NOISE = "noise"  # bytes before a start character
    BAD_LENGTH = "bad_length"  # a start character followed by an impossible length
    CHECKSUM = "checksum"  # a complete candidate whose check character was wrong
    OVERFLOW = "overflow"  # a candidate longer than the framer accepts
    GAP = "gap"  # an unfinished frame abandoned after an inter-character gap


@dataclass(slots=True, frozen=True)
class Frame:
    """One whole frame whose framing and checksum are right."""

    data: bytes


@dataclass(slots=True, frozen=True)
class Skipped:
    """Bytes that did not make a frame, with the reason."""

    data: bytes
    reason: SkipReason


class Framer(Protocol):
    """The incremental framer every codec provides."""

    def feed(self, data: bytes) -> None:
        """Append received bytes."""

    def next_frame(self) -> Frame | Skipped | None:
        """Return the next frame or skipped piece, or None when more bytes are needed."""

    def reset(self) -> None:
        """Mark an inter-character gap: an unfinished frame begun before it is given up.

        Its bytes come out of :meth:`next_frame` as skipped, reason ``gap``.
        """

    @property
    def buffered(self) -> int:
        """Number of bytes fed but not yet handed out."""


class FramerBuffer:
    """The bookkeeping every vendor framer shares: received bytes and the last gap.

    A vendor framer subclasses this and writes only :meth:`next_frame`, cutting what it
    recognises off the head of ``_buf`` with :meth:`_take` or :meth:`_skip`. ``_horizon``
    is the number of buffered bytes that arrived before the last :meth:`reset` (0: no gap
    since): a candidate frame that starts before it must also end before it.
    """

    __slots__ = ("_buf", "_horizon")

    def __init__(self) -> None:
        self._buf = bytearray()
        self._horizon = 0

    def feed(self, data: bytes) -> None:
        """Append received bytes."""
        self._buf += data

    @property
    def buffered(self) -> int:
        """Bytes fed but not yet handed out."""
        return len(self._buf)

    def reset(self) -> None:
        """Mark an inter-character gap: a frame begun before it may not wait for more bytes."""
        self._horizon = len(self._buf)

    def _take(self, count: int) -> bytes:
        """Cut ``count`` bytes off the head of the buffer."""
        data = bytes(self._buf[:count])
        del self._buf[:count]
        self._horizon = max(0, self._horizon - count)
        return data

    def _skip(self, count: int, reason: SkipReason) -> Skipped:
        """Cut ``count`` bytes off the head as a skipped piece."""
        return Skipped(self._take(count), reason)
