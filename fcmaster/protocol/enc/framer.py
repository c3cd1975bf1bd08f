"""Cuts a received byte stream into checked ENC frames (§3, §5, §9).

Theory of operation: the buffer head is either noise (anything but ``~``), handed back at
once up to the next ``~``, or a candidate starting with ``~``. A candidate is scanned
until the first byte that is not an uppercase hex digit:

* CR ends it. It is a frame when it is 10-18 bytes long (a frame-error reply may leave out
  the index and data areas, §5) and its last four characters are the sum of the others
  (§3.1); otherwise the whole candidate is skipped (``bad_length`` or ``checksum``).
* ``~`` means the candidate was cut short and a new one starts: everything before it is
  skipped (``bad_length``).
* Any other byte cannot be in a frame (§3: lowercase and non-ASCII bytes are invalid):
  the candidate up to that byte is skipped (``noise``), and the byte itself goes with the
  noise that follows.

A candidate that reaches 18 bytes without CR is skipped (``overflow``), so the framer
never holds more than 17 bytes. Since ``~`` and CR cannot occur inside a frame, skipping a
whole rejected candidate never hides a frame that starts inside it.

Nothing here knows about time: when the bus sees an inter-character gap it calls
:meth:`EncFramer.reset`, and a candidate begun before the gap that did not end before it
is given up (``gap``) instead of being completed with bytes of a later frame, whether
those bytes are fed before or after the next call.
"""

from __future__ import annotations

from fcmaster.protocol.enc.frame import (
    CHECKSUM_CHARS,
    END,
    HEAD,
    HEX_DIGITS,
    MAX_LENGTH,
    MIN_LENGTH,
    checksum,
)
from fcmaster.protocol.framing import Frame, FramerBuffer, Skipped, SkipReason


class EncFramer(FramerBuffer):
    """Incremental framer for ENC frames in either direction; fed any chunks, it never raises."""

    __slots__ = ()

    def next_frame(self) -> Frame | Skipped | None:
        """Return the next checked frame or skipped piece, or None if more bytes are needed."""
        buf = self._buf
        if not buf:
            return None
        if buf[0] != HEAD:
            start = buf.find(HEAD)
            return self._skip(len(buf) if start < 0 else start, SkipReason.NOISE)
        # A candidate begun before a gap must also end before it: bytes fed after reset()
        # belong to a later frame, even when they arrive before the next call here.
        end = min(self._horizon or len(buf), MAX_LENGTH)
        for position in range(1, end):
            byte = buf[position]
            if byte in HEX_DIGITS:
                continue
            if byte == END:
                return self._candidate(position + 1)
            if byte == HEAD:
                return self._skip(position, SkipReason.BAD_LENGTH)
            return self._skip(position, SkipReason.NOISE)
        if end == MAX_LENGTH:
            return self._skip(MAX_LENGTH, SkipReason.OVERFLOW)
        if self._horizon:
            return self._skip(self._horizon, SkipReason.GAP)
        return None

    def _candidate(self, length: int) -> Frame | Skipped:
        if length < MIN_LENGTH:
            return self._skip(length, SkipReason.BAD_LENGTH)
        body = self._buf[1 : length - 1 - CHECKSUM_CHARS]
        sent = bytes(self._buf[length - 1 - CHECKSUM_CHARS : length - 1])
        if int(sent, 16) != checksum(body):
            return self._skip(length, SkipReason.CHECKSUM)
        return Frame(self._take(length))
