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
