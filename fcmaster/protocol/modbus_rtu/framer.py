"""Cuts a received byte stream into checked Modbus RTU frames, by length.

RTU has no start character: a frame is told by the silence before it (3.5 characters,
Serial Line §2.5.1.1) and by its length, which its function code gives (frame.py's table).
The silence is measured by the bus, which calls :meth:`RtuFramer.reset`; the rest is here.

Theory of operation. A *candidate* starts at a byte that can be an address followed by a
byte that can be a function code of the direction read (answers from 1-247 with 03, 04,
06, 16 or an exception; requests to 0-247 with 03, 04, 06 or 16). Bytes before the first
such place are noise, handed back at once. A candidate's length comes from its function
code (and byte count); one whose byte count is impossible gives up its first byte
(``bad_length``), and so does one whose CRC is wrong once it is complete (``checksum``),
and the rest is scanned again: a real frame that starts inside noise or inside a broken
candidate is still found. A candidate begun before the last gap must also end before it; if
it cannot, it gives up its first byte (``gap``) instead of being completed with bytes of a
later frame, whether those were fed before or after the next call.

The longest frame is 255 bytes (a read answer of 125 registers, a write of 123), so a
drained framer holds at most 254 bytes.
"""

from __future__ import annotations

import enum
from typing import Final

from fcmaster.protocol.framing import Frame, FramerBuffer, Skipped, SkipReason
from fcmaster.protocol.modbus_rtu.crc import crc_ok
from fcmaster.protocol.modbus_rtu.frame import (
    EXCEPTION_BIT,
    EXCEPTION_LENGTH,
    FUNCTIONS,
    MAX_READ,
    MAX_WRITE,
    WRITE_REPLY_LENGTH,
    Function,
)

MAX_FRAME: Final = 255
_NEED_MORE: Final = 0
_IMPOSSIBLE: Final = -1
_READS: Final = (Function.READ_HOLDING, Function.READ_INPUT)


class Direction(enum.Enum):
    """Which frames a framer cuts out: a master reads responses, a server requests."""

    RESPONSES = "responses"
    REQUESTS = "requests"


# An exception may answer any function (a drive may have been asked one by another master).
_ANSWER_FUNCTIONS: Final = frozenset(FUNCTIONS | set(range(EXCEPTION_BIT + 1, 0x100)))
_FIRST_ADDRESS: Final = {Direction.RESPONSES: 1, Direction.REQUESTS: 0}
_STARTS: Final = {Direction.RESPONSES: _ANSWER_FUNCTIONS, Direction.REQUESTS: FUNCTIONS}


class RtuFramer(FramerBuffer):
    """Incremental framer for RTU frames of one direction; fed any chunks, it never raises."""

    __slots__ = ("_direction", "_first_address", "_functions")

    def __init__(self, direction: Direction = Direction.RESPONSES) -> None:
        super().__init__()
        self._direction = direction
        self._first_address = _FIRST_ADDRESS[direction]
        self._functions = _STARTS[direction]

    def next_frame(self) -> Frame | Skipped | None:
        """Return the next checked frame or skipped piece, or None if more bytes are needed."""
        buf = self._buf
        if not buf:
            return None
        start = self._first_candidate()
        if start:
            return self._skip(start, SkipReason.NOISE)
        length = self._length()
        if length == _IMPOSSIBLE:
            return self._skip(1, SkipReason.BAD_LENGTH)
        # A candidate begun before a gap must also end before it.
        limit = self._horizon or len(buf)
        if length == _NEED_MORE or length > limit:
            return self._skip(1, SkipReason.GAP) if self._horizon else None
        if not crc_ok(memoryview(buf)[:length]):
            return self._skip(1, SkipReason.CHECKSUM)
        return Frame(self._take(length))

    def _first_candidate(self) -> int:
        """Where the first byte that can begin a frame is (the buffer's length: nowhere)."""
        buf, functions, first = self._buf, self._functions, self._first_address
        last = len(buf) - 1
        for position, byte in enumerate(buf):
            # An address whose function code has not come yet may still begin one.
            if first <= byte <= 247 and (position == last or buf[position + 1] in functions):
                return position
        return len(buf)

    def _length(self) -> int:
        """The candidate's length in bytes, ``_NEED_MORE`` or ``_IMPOSSIBLE``."""
        buf = self._buf
        if len(buf) < 2:
            return _NEED_MORE
        function = buf[1]
        if self._direction is Direction.RESPONSES:
            if function & EXCEPTION_BIT:
                return EXCEPTION_LENGTH
            if function in _READS:
                if len(buf) < 3:
                    return _NEED_MORE
                size = buf[2]
                ok = size and not size % 2 and size <= 2 * MAX_READ
                return 5 + size if ok else _IMPOSSIBLE
            return WRITE_REPLY_LENGTH
        if function != Function.WRITE_MULTIPLE:
            return 8  # address, function, two words, CRC
        if len(buf) < 7:
            return _NEED_MORE
        count = buf[4] << 8 | buf[5]
        ok = 1 <= count <= MAX_WRITE and buf[6] == 2 * count
        return 9 + buf[6] if ok else _IMPOSSIBLE
