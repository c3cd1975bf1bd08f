"""How the simulated Mitsubishi drives cut the master's bytes into requests.

The codec's framer (:class:`~fcmaster.protocol.mitsubishi.framer.MitsubishiFramer`) hands
out only frames whose sum check is right, which is what a master wants. A drive must see
the broken ones too, because it answers them: NAK 2 for a wrong sum, NAK 7 for a character
that is not 0-9/A-F, NAK 3 for a request of no known shape (protocols/mitsubishi.md §5).
So this receiver cuts candidates by their delimiters only and leaves the judging to the
drive:

* ENQ … up to the terminator the line is set to (Pr.124: CR, or CR LF), at most
  :data:`MAX_REQUEST` bytes; a candidate that never ends is dropped at the next start
  character.
* With no terminator (Pr.124 = 0) the length follows from the instruction code
  (``request_widths``: the same rule the codec's framer and the drive use) and whether the
  waiting-time digit travels (Pr.123 = 9999); four or six digits are told apart by the sum
  check.
* ACK st / NAK st [t]: the master's optional answer to a data reply (§2 step 5), handed on
  as a frame so the drives can ignore it.

Every drive on the line shares this one receiver, so they must agree on Pr.123 and Pr.124,
as the protocol document asks of a line anyway (§1.1).
"""

from __future__ import annotations

from typing import Final

from fcmaster.protocol.framing import Frame, FramerBuffer, Skipped, SkipReason
from fcmaster.protocol.mitsubishi.instructions import request_widths
from fcmaster.protocol.mitsubishi.message import ACK, CR, ENQ, LF, NAK, Terminator, sum_check

MAX_REQUEST: Final = 20  # HF0 with the waiting time and CR LF (§6)
_STARTS: Final = (ENQ, ACK, NAK)
_HEX: Final = frozenset(b"0123456789ABCDEF")


class RequestReceiver(FramerBuffer):
    """Cuts request candidates out of the master's bytes; never raises."""

    __slots__ = ("_terminator", "_wait_digit")

    def __init__(self, *, terminator: Terminator, wait_digit: bool) -> None:
        super().__init__()
        self._terminator = terminator
        self._wait_digit = wait_digit

    def next_frame(self) -> Frame | Skipped | None:
        """The next candidate or skipped piece; None when more bytes are needed."""
        buf = self._buf
        if not buf:
            return None
        if buf[0] not in _STARTS:
            return self._skip(self._next_start(0), SkipReason.NOISE)
        at_gap = self._horizon > 0
        if buf[0] == ENQ:
            length = (
                self._unterminated_length()
                if self._terminator is Terminator.NONE
                else self._terminated_length(1)
            )
        else:
            length = self._terminated_length(1) if self._terminator is not Terminator.NONE else 3
            longest = 4 + len(self._terminator.suffix)  # NAK st e and the terminator
            if isinstance(length, int) and length > longest:
                return self._skip(1, SkipReason.BAD_LENGTH)
        if isinstance(length, SkipReason):
            return self._skip(self._next_start(1), length)
        if length is None or length > len(buf):
            return self._skip(len(buf), SkipReason.GAP) if at_gap else None
        return Frame(self._take(length))

    def _next_start(self, after: int) -> int:
        found = [i for i in (self._buf.find(s, after) for s in _STARTS) if i >= 0]
        return min(found) if found else len(self._buf)

    def _terminated_length(self, start: int) -> int | SkipReason | None:
        """Up to and including CR (and LF after it when the line sends CR LF)."""
        buf = self._buf
        for i in range(start, min(len(buf), MAX_REQUEST)):
            if buf[i] == CR:
                if self._terminator is Terminator.CRLF:
                    if i + 1 >= len(buf):
                        return None  # the LF is on its way
                    return i + 2 if buf[i + 1] == LF else i + 1
                return i + 1
            if buf[i] in _STARTS:
                return SkipReason.BAD_LENGTH  # a new request began: this one never ended
        return SkipReason.BAD_LENGTH if len(buf) >= MAX_REQUEST else None

    def _unterminated_length(self) -> int | SkipReason | None:
        buf = self._buf
        first_data = 5 + self._wait_digit
        if len(buf) < 5:
            return None
        if not _HEX.issuperset(buf[3:5]):
            return SkipReason.BAD_LENGTH  # no way to tell how long it is
        widths = request_widths(int(buf[3:5], 16))
        # The width whose sum is right; the first when none is, and the drive NAKs the sum.
        for width in widths:
            end = first_data + width + 2
            if len(buf) < end:
                return None
            if _sum_ok(buf[1 : end - 2], buf[end - 2 : end]):
                return end
        return first_data + widths[0] + 2


def _sum_ok(checked: bytes | bytearray, digits: bytes | bytearray) -> bool:
    return _HEX.issuperset(digits) and int(digits, 16) == sum_check(checked)
