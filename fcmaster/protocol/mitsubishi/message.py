"""Computer-link frames: the bytes on the wire and back (protocols/mitsubishi.md §3, §4, §6).

::

    request      ENQ st ic [w] [data] sc [t]     data: 0 (read), 2, 4, 6 or 10 (HF0) digits
    data reply   STX st data ETX sc [t]          data: 2, 4, 6, 12 (HF0 reply) digits, or 20 text
    ack          ACK st [t]
    nak          NAK st e [t]                    from a drive; the master's own NAK has no e

* Every field is uppercase hexadecimal ASCII, most significant digit first (§3). Lowercase
  a-f is a character error on the drive, so it is refused here too.
* The sum check is the low byte of the sum of the ASCII codes after ENQ/STX up to the last
  data character (before ETX), as two hex digits (§4). ACK and NAK frames have none.
* ``[w]`` (the waiting-time digit) is there only when the drive's Pr.123/Pr.337 is 9999, and
  ``[t]`` is what Pr.124/Pr.341 selects (§1.1). Both are line settings, not message fields:
  the encoder takes them as arguments and the decoder reads them off the frame. Without the
  waiting-time digit a request's body has an even number of characters, with it an odd one
  (station, code, sum and every data width are even), so a request tells which it is.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Final

from fcmaster.errors import MalformedReply, UsageError

# Control codes (§3).
STX: Final = 0x02
ETX: Final = 0x03
ENQ: Final = 0x05
ACK: Final = 0x06
LF: Final = 0x0A
CR: Final = 0x0D
NAK: Final = 0x15

MAX_STATION: Final = 31  # stations 0-31, sent as "00"-"1F" (§3)
MAX_WAIT_MS: Final = 150  # waiting time 0-150 ms in 10 ms steps, one hex digit (§3)
WAIT_STEP_MS: Final = 10

REQUEST_WIDTHS: Final = (0, 2, 4, 6, 10)  # read, A1/A', A, A2/A'', multi command (§6)
REPLY_WIDTHS: Final = (2, 4, 6, 12, 20)  # E1/E', E, E2/E'', C1, E3 (§6)
TEXT_WIDTH: Final = 20  # E3: the model name, 20 characters of text
HEX_DIGITS: Final = frozenset(b"0123456789ABCDEF")


class Terminator(enum.StrEnum):
    """What ends every frame, as the drive's Pr.124/Pr.341 says (§1.1)."""

    NONE = "none"  # Pr.124 = 0
    CR = "cr"  # Pr.124 = 1, the factory setting
    CRLF = "crlf"  # Pr.124 = 2

    @property
    def suffix(self) -> bytes:
        """The bytes that end a frame."""
        return _SUFFIXES[self]


_SUFFIXES: Final = {Terminator.NONE: b"", Terminator.CR: b"\r", Terminator.CRLF: b"\r\n"}


@dataclass(slots=True, frozen=True, kw_only=True)
class Request:
    """A master → drive request: a read (``data`` None) or a write (§6 A, A1, A2, B).

    ``width`` is the number of data digits (0 for a read); the instruction code fixes it
    (§9). ``wait_ms`` is the waiting-time digit, or None when the line leaves it out.
    """

    station: int
    instruction: int
    data: int | None = None
    width: int = 0
    wait_ms: int | None = None

    @property
    def is_read(self) -> bool:
        """Whether this asks for data (format B) rather than writing it."""
        return self.data is None


@dataclass(slots=True, frozen=True, kw_only=True)
class DataReply:
    """A drive's read reply (§6 E, E1, E2, E3, C1).

    ``data`` is the hexadecimal value; for the model name (E3) it is None and ``text``
    holds the 20 characters instead.
    """

    station: int
    data: int | None
    width: int
    text: str | None = None


@dataclass(slots=True, frozen=True)
class Ack:
    """ACK: a write accepted (§6 C), or the master's "reply received" (§6 G)."""

    station: int


@dataclass(slots=True, frozen=True)
class Nak:
    """NAK: a drive's refusal with its error code (§6 D, F, §5).

    The master's own "send the reply again" (§6 H) has no error code: ``error_code`` None.
    """

    station: int
    error_code: int | None = None


Message = Request | DataReply | Ack | Nak


def sum_check(chars: bytes | bytearray | memoryview) -> int:
    """The low byte of the sum of ``chars`` (the checked characters, §4)."""
    return sum(chars) & 0xFF


def _hex(value: int, digits: int) -> bytes:
    return f"{value:0{digits}X}".encode("ascii")


def _check_station(station: int) -> None:
    if not 0 <= station <= MAX_STATION:
        raise UsageError(f"station {station} is outside 0-31")


def wait_digit(wait_ms: int) -> int:
    """The waiting-time digit for ``wait_ms`` (0-150 ms in 10 ms steps, §3)."""
    if not 0 <= wait_ms <= MAX_WAIT_MS or wait_ms % WAIT_STEP_MS:
        raise UsageError(f"waiting time {wait_ms} ms is not one of 0, 10, … 150 ms")
    return wait_ms // WAIT_STEP_MS


def encode_frame(message: Message, terminator: Terminator = Terminator.CR) -> bytes:
    """Return the bytes of ``message`` on the wire, sum check and terminator included."""
    if isinstance(message, Request):
        body = _request_body(message)
        return bytes((ENQ,)) + body + _hex(sum_check(body), 2) + terminator.suffix
    _check_station(message.station)
    station = _hex(message.station, 2)
    if isinstance(message, DataReply):
        body = station + _reply_data(message)
        return bytes((STX,)) + body + bytes((ETX,)) + _hex(sum_check(body), 2) + terminator.suffix
    if isinstance(message, Ack):
        return bytes((ACK,)) + station + terminator.suffix
    code = b""
    if message.error_code is not None:
        if not 0 <= message.error_code <= 0xF:
            raise UsageError(f"error code {message.error_code} is not one hex digit")
        code = _hex(message.error_code, 1)
    return bytes((NAK,)) + station + code + terminator.suffix


def _request_body(request: Request) -> bytes:
    _check_station(request.station)
    if not 0 <= request.instruction <= 0xFF:
        raise UsageError(f"instruction code {request.instruction} is not two hex digits")
    body = _hex(request.station, 2) + _hex(request.instruction, 2)
    if request.wait_ms is not None:
        body += _hex(wait_digit(request.wait_ms), 1)
    # Read codes are 00-7F and write codes 80-FF (§9): a read carries no data.
    if request.data is None:
        if request.width or request.instruction >= 0x80:
            raise UsageError(f"H{request.instruction:02X} is not a read code (00-7F)")
        return body
    if request.instruction < 0x80:
        raise UsageError(f"H{request.instruction:02X} is not a write code (80-FF)")
    if request.width not in REQUEST_WIDTHS[1:]:
        raise UsageError(f"a request carries 2, 4, 6 or 10 data digits, not {request.width}")
    if not 0 <= request.data < 16**request.width:
        raise UsageError(f"data {request.data} does not fit in {request.width} hex digits")
    return body + _hex(request.data, request.width)


def _reply_data(reply: DataReply) -> bytes:
    if reply.width == TEXT_WIDTH:
        text = reply.text or ""
        if reply.data is not None or len(text) != TEXT_WIDTH or not _is_text(text):
            raise UsageError("a model-name reply carries exactly 20 printable characters")
        return text.encode("ascii")
    if reply.width not in REPLY_WIDTHS or reply.data is None or reply.text is not None:
        raise UsageError(f"a data reply carries 2, 4, 6, 12 digits or 20 characters: {reply}")
    if not 0 <= reply.data < 16**reply.width:
        raise UsageError(f"data {reply.data} does not fit in {reply.width} hex digits")
    return _hex(reply.data, reply.width)


def _is_text(text: str) -> bool:
    return all(" " <= ch <= "~" for ch in text)


def split_terminator(frame: bytes) -> tuple[bytes, Terminator]:
    """Split a frame into what precedes its CR/LF and the terminator it ends with."""
    if frame.endswith(b"\r\n"):
        return frame[:-2], Terminator.CRLF
    if frame.endswith(b"\r"):
        return frame[:-1], Terminator.CR
    return frame, Terminator.NONE


def decode_frame(frame: bytes, *, check_sum: bool = True) -> Message:
    """Decode one whole frame (with or without its terminator) into a message.

    Raises MalformedReply when the frame is not one of the shapes of §6, holds a character
    other than uppercase hex where a field is, or (with ``check_sum``) its sum check is wrong.
    """
    body, _ = split_terminator(frame)
    if not body:
        raise MalformedReply("empty frame", raw=frame)
    start, rest = body[0], body[1:]
    if start == ACK:
        if len(rest) != 2:
            raise MalformedReply(f"ACK is followed by {len(rest)} characters, not 2", raw=frame)
        return Ack(_station(rest, frame))
    if start == NAK:
        if len(rest) not in (2, 3):
            raise MalformedReply(f"NAK is followed by {len(rest)} characters", raw=frame)
        code = _hex_value(rest[2:], frame) if len(rest) == 3 else None
        return Nak(_station(rest, frame), code)
    if start == STX:
        return _decode_data_reply(rest, frame, check_sum=check_sum)
    if start == ENQ:
        return _decode_request(rest, frame, check_sum=check_sum)
    raise MalformedReply(f"frame starts with 0x{start:02X}, not ENQ, STX, ACK or NAK", raw=frame)


def _decode_data_reply(rest: bytes, frame: bytes, *, check_sum: bool) -> DataReply:
    # rest = st data ETX sc
    if len(rest) < 5 or rest[-3] != ETX:
        raise MalformedReply("a data reply ends with ETX and two sum-check digits", raw=frame)
    checked, sc = rest[:-3], rest[-2:]
    width = len(checked) - 2
    if width not in REPLY_WIDTHS:
        raise MalformedReply(f"a data reply cannot carry {width} characters", raw=frame)
    station = _station(checked, frame)
    received = _hex_value(sc, frame)
    if check_sum and received != sum_check(checked):
        raise MalformedReply(
            f"sum check {received:02X}, the characters add up to {sum_check(checked):02X}",
            raw=frame,
        )
    if width == TEXT_WIDTH:
        text = checked[2:].decode("ascii", errors="replace")
        if not _is_text(text):
            raise MalformedReply("the model name holds a character that is not text", raw=frame)
        return DataReply(station=station, data=None, width=width, text=text)
    return DataReply(station=station, data=_hex_value(checked[2:], frame), width=width)


def _decode_request(rest: bytes, frame: bytes, *, check_sum: bool) -> Request:
    # rest = st ic [w] data sc; an odd length means the waiting-time digit is there.
    has_wait = len(rest) % 2 == 1
    width = len(rest) - 6 - has_wait
    if width not in REQUEST_WIDTHS:
        raise MalformedReply(f"a request of {len(rest) + 1} characters is no format", raw=frame)
    checked, sc = rest[:-2], rest[-2:]
    station = _station(checked, frame)
    instruction = _hex_value(checked[2:4], frame)
    wait_ms = _hex_value(checked[4:5], frame) * WAIT_STEP_MS if has_wait else None
    data = _hex_value(checked[4 + has_wait :], frame) if width else None
    received = _hex_value(sc, frame)
    if check_sum and received != sum_check(checked):
        raise MalformedReply(
            f"sum check {received:02X}, the characters add up to {sum_check(checked):02X}",
            raw=frame,
        )
    return Request(
        station=station, instruction=instruction, data=data, width=width, wait_ms=wait_ms
    )


def _station(chars: bytes, frame: bytes) -> int:
    station = _hex_value(chars[:2], frame)
    if station > MAX_STATION:
        raise MalformedReply(f"station H{station:02X} is beyond 31 (H1F)", raw=frame)
    return station


def _hex_value(chars: bytes, frame: bytes) -> int:
    if not chars or not HEX_DIGITS.issuperset(chars):
        raise MalformedReply(f"{chars!r} is not uppercase hexadecimal", raw=frame)
    return int(chars, 16)


def frame_length(message: Message, terminator: Terminator) -> int:
    """Bytes ``message`` takes on the wire (a cheap ``len(encode_frame(...))``)."""
    suffix = len(terminator.suffix)
    if isinstance(message, Request):
        return 7 + (message.wait_ms is not None) + message.width + suffix
    if isinstance(message, DataReply):
        return 6 + message.width + suffix
    if isinstance(message, Ack):
        return 3 + suffix
    return 3 + (message.error_code is not None) + suffix
