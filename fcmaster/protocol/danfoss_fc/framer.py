"""Cuts a received byte stream into checked FC telegrams.

Theory of operation: the buffer head is either noise (anything but STX), which is handed
back at once, or a candidate telegram starting with STX. A candidate is judged by its LGE
(must be 6, 14 or 10 + a text length within ``max_text_length``), then, once LGE + 2 bytes
are in, by its BCC. A rejected candidate gives up only its STX byte and the rest is
scanned again, so a real telegram that starts inside noise or inside a broken candidate is
still found. Nothing here knows about time: when the bus sees an inter-character gap it
calls :meth:`FcFramer.reset`, and candidates that started before the gap but did not end
before it are given up the same way (reason ``gap``) instead of being completed with bytes
of a later telegram, whether those bytes are fed before or after the next call.
"""

from __future__ import annotations

from fcmaster.protocol.danfoss_fc.telegram import LGE_PROCESS, LGE_TEXT_BASE, STX, bcc
from fcmaster.protocol.framing import Frame, FramerBuffer, Skipped, SkipReason

DEFAULT_MAX_TEXT_LENGTH = 64  # drive identification texts (15-4x) are at most 40 characters


class FcFramer(FramerBuffer):
    """Incremental framer for FC telegrams; fed any chunks, it never raises."""

    __slots__ = ("_max_lge",)

    def __init__(self, *, max_text_length: int = DEFAULT_MAX_TEXT_LENGTH) -> None:
        super().__init__()
        self._max_lge = min(LGE_TEXT_BASE + max_text_length, 0xFF)

    def next_frame(self) -> Frame | Skipped | None:
        """Return the next checked frame or skipped piece, or None if more bytes are needed."""
        buf = self._buf
        if not buf:
            return None
        if buf[0] != STX:
            start = buf.find(STX)
            return self._skip(len(buf) if start < 0 else start, SkipReason.NOISE)
        # A candidate begun before a gap must also end before it: bytes fed after reset()
        # belong to a later telegram, even when they arrive before the next call here.
        end = self._horizon or len(buf)
        if end < 2:
            return self._skip(1, SkipReason.GAP) if self._horizon else None
        lge = buf[1]
        if lge != LGE_PROCESS and lge < LGE_TEXT_BASE:
            return self._skip(1, SkipReason.BAD_LENGTH)
        if lge > self._max_lge:
            return self._skip(1, SkipReason.OVERFLOW)
        total = lge + 2
        if end < total:
            return self._skip(1, SkipReason.GAP) if self._horizon else None
        if bcc(memoryview(buf)[:total]) != 0:
            return self._skip(1, SkipReason.CHECKSUM)
        return Frame(self._take(total))
