"""Cuts a byte stream into checked computer-link frames (protocols/mitsubishi.md §6, §12).

Theory of operation: the buffer head is either noise (anything but a start character),
handed back at once up to the next start character, or a candidate frame. Replies start
with STX, ACK or NAK; requests (``from_drive=False``, for a simulated drive) with ENQ, ACK
or NAK. A candidate is judged field by field as its bytes arrive:

* ACK st, NAK st e (a drive's NAK; the master's own has no e): fixed lengths, hex fields.
* STX st data ETX sc: the data runs to the first ETX and must be 2, 4, 6 or 12 hex digits
  or 20 characters of text (the model name); then the sum check must match.
* ENQ st ic [w] data sc: the instruction code fixes the data width (§9, ``request_widths``):
  none for a read code, 2 for HFA/HF3/HFF/HEC, 10 for HF0, otherwise 4 or 6, settled by the
  sum check (and the terminator); ``wait_digit`` says whether the line carries the
  waiting-time digit.
* Then the terminator the line is set to (Pr.124). With CR + LF a missing LF is tolerated
  (§12): the frame ends after CR when the next byte is not LF, or at a gap. A missing CR is
  not: ACK and NAK frames have no sum check, and the terminator is the only thing that
  tells a real one from noise that happens to look like one.

A rejected candidate gives up only its start byte and the rest is scanned again, so a frame
that starts inside noise or inside a broken candidate is still found. Nothing here knows
about time: when the bus sees an inter-character gap it calls :meth:`MitsubishiFramer.reset`,
and a candidate that began before the gap must also end before it (reason ``gap``
otherwise), whether the later bytes are fed before or after the next call. No candidate is
longer than 28 bytes, so the buffer never holds more than that once drained.
"""

from __future__ import annotations

from typing import Final

from fcmaster.protocol.framing import Frame, FramerBuffer, Skipped, SkipReason
from fcmaster.protocol.mitsubishi.instructions import request_widths
from fcmaster.protocol.mitsubishi.message import (
    ACK,
    CR,
    ENQ,
    ETX,
    HEX_DIGITS,
    LF,
    NAK,
    STX,
    TEXT_WIDTH,
    Terminator,
    sum_check,
)

MAX_FRAME_LENGTH: Final = 28  # E3 with CR LF (§6)
_DATA_WIDTHS: Final = frozenset((2, 4, 6, 12))

# What a judge returns: a frame length, a reason to give up the start byte, or None (wait).
_Verdict = int | SkipReason | None


class MitsubishiFramer(FramerBuffer):
    """Incremental framer for computer-link frames; fed any chunks, it never raises."""

    __slots__ = ("_from_drive", "_starts", "_terminator", "_wait_digit")

    def __init__(
        self,
        *,
        terminator: Terminator = Terminator.CR,
        from_drive: bool = True,
        wait_digit: bool = True,
    ) -> None:
        super().__init__()
        self._terminator = terminator
        self._from_drive = from_drive
        self._wait_digit = wait_digit  # requests only: Pr.123 = 9999
        self._starts = (STX, ACK, NAK) if from_drive else (ENQ, ACK, NAK)

    def next_frame(self) -> Frame | Skipped | None:
        """Return the next checked frame or skipped piece, or None if more bytes are needed."""
        buf = self._buf
        if not buf:
            return None
        start = buf[0]
        if start not in self._starts:
            found = [i for i in (buf.find(s) for s in self._starts) if i >= 0]
            return self._skip(min(found) if found else len(buf), SkipReason.NOISE)
        # A candidate begun before a gap must also end before it: bytes fed after reset()
        # belong to a later frame, even when they arrive before the next call here.
        at_gap = self._horizon > 0
        end = self._horizon or len(buf)
        if start == STX:
            verdict = self._judge_data_reply(end, at_gap)
        elif start == ENQ:
            verdict = self._judge_request(end, at_gap)
        else:
            # ACK st; NAK st e from a drive, NAK st from the master.
            length = 4 if start == NAK and self._from_drive else 3
            verdict = self._judge_fixed(length, end, at_gap)
        if verdict is None:
            return self._skip(1, SkipReason.GAP) if at_gap else None
        if isinstance(verdict, SkipReason):
            return self._skip(1, verdict)
        frame = self._take(verdict)
        return Frame(frame)

    def _judge_fixed(self, length: int, end: int, at_gap: bool) -> _Verdict:
        if not self._station_ok(end) or not self._hex_run(1, min(length, end)):
            return SkipReason.BAD_LENGTH
        if end < length:
            return None
        return self._terminated(length, end, at_gap)

    def _judge_data_reply(self, end: int, at_gap: bool) -> _Verdict:
        buf = self._buf
        if not self._station_ok(end) or not self._hex_run(1, min(3, end)):
            return SkipReason.BAD_LENGTH
        # The data runs to the first ETX; it is text (printable) until its width is known.
        etx = -1
        for i in range(3, min(end, 3 + TEXT_WIDTH + 1)):
            if buf[i] == ETX:
                etx = i
                break
            if not 0x20 <= buf[i] <= 0x7E:
                return SkipReason.BAD_LENGTH
        if etx < 0:
            return SkipReason.BAD_LENGTH if end > 3 + TEXT_WIDTH else None
        width = etx - 3
        if not (width == TEXT_WIDTH or (width in _DATA_WIDTHS and self._hex_run(3, etx))):
            return SkipReason.BAD_LENGTH
        if not self._hex_run(etx + 1, min(etx + 3, end)):
            return SkipReason.BAD_LENGTH
        if end < etx + 3:
            return None
        if int(buf[etx + 1 : etx + 3], 16) != sum_check(buf[1:etx]):
            return SkipReason.CHECKSUM
        return self._terminated(etx + 3, end, at_gap)

    def _judge_request(self, end: int, at_gap: bool) -> _Verdict:
        buf = self._buf
        first_data = 5 + self._wait_digit
        if not self._station_ok(end) or not self._hex_run(1, min(first_data, end)):
            return SkipReason.BAD_LENGTH
        if end < first_data:
            return None
        reason = SkipReason.BAD_LENGTH
        for width in request_widths(int(buf[3:5], 16)):
            sum_at = first_data + width
            if not self._hex_run(first_data, min(sum_at + 2, end)):
                return reason
            if end < sum_at + 2:
                return None
            if int(buf[sum_at : sum_at + 2], 16) != sum_check(buf[1:sum_at]):
                reason = SkipReason.CHECKSUM
                continue
            verdict = self._terminated(sum_at + 2, end, at_gap)
            if not isinstance(verdict, SkipReason):
                return verdict
            reason = verdict
        return reason

    def _terminated(self, length: int, end: int, at_gap: bool) -> _Verdict:
        """The frame's length once its terminator is checked (``length`` without it)."""
        terminator = self._terminator
        if terminator is Terminator.NONE:
            return length
        if end <= length:
            return None
        if self._buf[length] != CR:
            return SkipReason.BAD_LENGTH
        if terminator is Terminator.CR:
            return length + 1
        if end <= length + 1:
            return length + 1 if at_gap else None  # §12: a missing LF is tolerated
        return length + 2 if self._buf[length + 1] == LF else length + 1

    def _station_ok(self, end: int) -> bool:
        # Stations are 00-1F (§3): a first digit other than 0 or 1 is noise, not a frame.
        return end < 2 or self._buf[1] in b"01"

    def _hex_run(self, start: int, stop: int) -> bool:
        return HEX_DIGITS.issuperset(self._buf[start:stop])
