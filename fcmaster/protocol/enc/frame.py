"""ENC "~" frames: the bytes on the wire and back (protocols/enc.md §3).

::

    ~ | AA | CC | XX II | DDDD | SSSS | CR        request  (master → drive)
    ~ | AA | RR | FF II | DDDD | SSSS | CR        response (drive → master)

* Every field is uppercase hexadecimal ASCII; lowercase ``a``-``f`` is invalid (§3).
* AA address, CC command, XX auxiliary index, II command index, DDDD data (optional:
  14-byte frames have none, 18-byte frames have it), SSSS the checksum (§3.1).
* In a response RR is the response code and FF the failure index (the fault code) (§3, §5).
  A frame-error response may leave out the index and data areas (§5), so a response body
  is 4, 8 or 12 characters.

This module keeps every two-character field as the byte it spells in hexadecimal. How a
number is *written* into such a byte — hexadecimal like the commands, or as the manual
prints it in decimal digits — is an open question for addresses, response codes and fault
codes (§10); :mod:`fcmaster.protocol.enc.codes` settles it per line.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Final

from fcmaster.errors import MalformedReply, UsageError

HEAD: Final = 0x7E  # "~" (§3)
END: Final = 0x0D  # CR (§3)
HEX_DIGITS: Final = frozenset(b"0123456789ABCDEF")  # the legal field characters (§3)

CHECKSUM_CHARS: Final = 4  # §3.1
SHORT_LENGTH: Final = 14  # a frame without data area (§3)
LONG_LENGTH: Final = 18  # a frame with data area (§3)
MIN_LENGTH: Final = 10  # a frame-error reply with only address and response code (§5)
MAX_LENGTH: Final = LONG_LENGTH

BROADCAST: Final = 127  # F2.15: frames to 127 get no reply (§1, §2)

_REQUEST_BODIES: Final = (8, 12)  # address + command + index (+ data)
_RESPONSE_BODIES: Final = (4, 8, 12)  # address + response (+ index (+ data))


class Command(enum.IntEnum):
    """Commands as the manual numbers them; the wire carries the hex value (§4)."""

    LOOK_UP_STATE = 10
    READ_VALUE = 11
    RUN_CONTROL = 12
    READ_PARAMETER = 13
    WRITE_PARAMETER = 14
    SOFTWARE_VERSION = 15


class RunControl(enum.IntEnum):
    """Command-12 indexes (§4.2, EDS300 table)."""

    RUN = 0x00
    SET_FREQUENCY = 0x01
    RUN_WITH_FREQUENCY = 0x02
    FORWARD = 0x03
    REVERSE = 0x04
    FORWARD_WITH_FREQUENCY = 0x05
    REVERSE_WITH_FREQUENCY = 0x06
    STOP = 0x07
    JOG = 0x08
    JOG_FORWARD = 0x09
    JOG_REVERSE = 0x0A
    STOP_JOG = 0x0B
    FAULT_RESET = 0x0C
    EMERGENCY_STOP = 0x0D


# §4.2: send data exactly where the manual's examples do.
RUN_CONTROL_WITH_DATA: Final = frozenset(
    (
        RunControl.SET_FREQUENCY,
        RunControl.RUN_WITH_FREQUENCY,
        RunControl.FORWARD_WITH_FREQUENCY,
        RunControl.REVERSE_WITH_FREQUENCY,
    )
)


@dataclass(slots=True, frozen=True, kw_only=True)
class Request:
    """A master → drive frame, every field as the byte its two hex characters spell."""

    address: int  # the address field (see codes.encode_number for its encoding)
    command: int  # 10-15 for the documented commands, sent as "0A"-"0F"
    aux_index: int = 0
    cmd_index: int = 0
    data: int | None = None  # None: a 14-byte frame

    @property
    def index(self) -> int:
        """The 16-bit index area: auxiliary index high, command index low (§3)."""
        return self.aux_index << 8 | self.cmd_index


@dataclass(slots=True, frozen=True, kw_only=True)
class Response:
    """A drive → master frame, every field as the byte its two hex characters spell.

    ``failure_index`` and ``cmd_index`` are None when the index area is left out (a
    frame-error reply, §5); ``data`` is None when the data area is.
    """

    address: int
    response: int
    failure_index: int | None = None
    cmd_index: int | None = None
    data: int | None = None


def checksum(body: bytes | bytearray | memoryview) -> int:
    """Sum of the ASCII codes from the first address character to the last data one (§3.1)."""
    return sum(body) & 0xFFFF


def encode_request(request: Request) -> bytes:
    """Return the wire bytes of ``request``, checksum and CR included."""
    body = _byte("address", request.address) + _byte("command", request.command)
    body += _byte("auxiliary index", request.aux_index) + _byte("command index", request.cmd_index)
    if request.data is not None:
        body += _word("data", request.data)
    return _close(body)


def encode_response(response: Response) -> bytes:
    """Return the wire bytes of ``response`` (the simulator's side of the line)."""
    body = _byte("address", response.address) + _byte("response", response.response)
    if response.failure_index is not None or response.cmd_index is not None:
        if response.failure_index is None or response.cmd_index is None:
            raise UsageError("a response carries both halves of its index area or neither")
        body += _byte("failure index", response.failure_index)
        body += _byte("command index", response.cmd_index)
    if response.data is not None:
        if response.cmd_index is None:
            raise UsageError("a response with a data area needs its index area too")
        body += _word("data", response.data)
    return _close(body)


def decode_request(frame: bytes) -> Request:
    """Decode a whole request frame; MalformedReply if it is not one."""
    body = _checked_body(frame, _REQUEST_BODIES)
    return Request(
        address=_hex(body[0:2]),
        command=_hex(body[2:4]),
        aux_index=_hex(body[4:6]),
        cmd_index=_hex(body[6:8]),
        data=_hex(body[8:12]) if len(body) == 12 else None,
    )


def decode_response(frame: bytes) -> Response:
    """Decode a whole response frame; MalformedReply if it is not one."""
    body = _checked_body(frame, _RESPONSE_BODIES)
    has_index = len(body) >= 8
    return Response(
        address=_hex(body[0:2]),
        response=_hex(body[2:4]),
        failure_index=_hex(body[4:6]) if has_index else None,
        cmd_index=_hex(body[6:8]) if has_index else None,
        data=_hex(body[8:12]) if len(body) == 12 else None,
    )


def split_frame(frame: bytes) -> tuple[bytes, int, bool]:
    """``(body, checksum_sent, checksum_ok)`` of a frame with head, legal characters and CR.

    Raises MalformedReply if ``frame`` is not shaped like a frame; a wrong checksum is
    reported, not raised, so a decoder for people can still show the fields.
    """
    if len(frame) < MIN_LENGTH or frame[0] != HEAD or frame[-1] != END:
        raise MalformedReply(
            f"not an ENC frame: it starts with ~, ends with CR and is {MIN_LENGTH}-"
            f"{MAX_LENGTH} bytes long",
            raw=frame,
        )
    if len(frame) > MAX_LENGTH:
        raise MalformedReply(f"{len(frame)} bytes is longer than {MAX_LENGTH}", raw=frame)
    inner = frame[1:-1]
    bad = next((byte for byte in inner if byte not in HEX_DIGITS), None)
    if bad is not None:
        raise MalformedReply(
            f"byte 0x{bad:02X} is not an uppercase hex digit (lowercase a-f is invalid)",
            raw=frame,
        )
    body, sent = inner[:-CHECKSUM_CHARS], _hex(inner[-CHECKSUM_CHARS:])
    return body, sent, checksum(body) == sent


def _checked_body(frame: bytes, lengths: tuple[int, ...]) -> bytes:
    body, sent, ok = split_frame(frame)
    if not ok:
        raise MalformedReply(
            f"checksum {sent:04X} does not match the sum {checksum(body):04X}", raw=frame
        )
    if len(body) not in lengths:
        raise MalformedReply(
            f"{len(body)} characters between address and checksum; expected "
            f"{' or '.join(str(n) for n in lengths)}",
            raw=frame,
        )
    return body


def _hex(chars: bytes) -> int:
    return int(chars, 16)


def _byte(name: str, value: int) -> bytes:
    if not 0 <= value <= 0xFF:
        raise UsageError(f"{name} {value} does not fit in two hex digits (0-255)")
    return b"%02X" % value


def _word(name: str, value: int) -> bytes:
    if not 0 <= value <= 0xFFFF:
        raise UsageError(f"{name} {value} does not fit in four hex digits (0-65535)")
    return b"%04X" % value


def _close(body: bytes) -> bytes:
    return bytes((HEAD,)) + body + b"%04X" % checksum(body) + bytes((END,))
