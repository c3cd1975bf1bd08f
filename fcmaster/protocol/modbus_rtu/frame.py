"""Modbus RTU frames of the four register functions: typed requests and responses ⇄ bytes.

An RTU frame is the server address (0 = broadcast, 1-247), the PDU — a function code and
its data, 16-bit fields big-endian — and the CRC, low byte first (Modbus over Serial Line
V1.02 §2.5.1; Application Protocol V1.1b3 §6.3, §6.4, §6.6, §6.12):

======================  ====================================  ===========================
function                request after the function code        response after the code
======================  ====================================  ===========================
03 read holding         start, count (1-125)                   byte count, registers
04 read input           start, count (1-125)                   byte count, registers
06 write single         register, value                        the request echoed
16 write multiple       start, count (1-123), byte count,      start, count
                        values
exception               —                                      function | 0x80, code
======================  ====================================  ===========================

A broadcast (address 0) reaches every server and is answered by none, so only writes may be
broadcast (Serial Line §2.1). The encoders refuse what the specification does not allow
(UsageError); the decoders raise :class:`~fcmaster.errors.MalformedReply` for a frame whose
fields disagree, never guess.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass
from typing import Final

from fcmaster.errors import MalformedReply, UsageError
from fcmaster.protocol.modbus_rtu.crc import crc_ok, with_crc

BROADCAST: Final = 0
ADDRESSES: Final = range(1, 248)  # 248-255 are reserved (Serial Line §2.2)
MAX_READ: Final = 125  # registers in one read (FC 3/4)
MAX_WRITE: Final = 123  # registers in one write (FC 16)
EXCEPTION_BIT: Final = 0x80
EXCEPTION_LENGTH: Final = 5  # address, function | 0x80, code, CRC
WRITE_REPLY_LENGTH: Final = 8  # FC 6 and FC 16 answers: address, function, 2 words, CRC

_WORDS: Final = struct.Struct(">HH")


class Function(enum.IntEnum):
    """The register functions a drive profile uses."""

    READ_HOLDING = 0x03
    READ_INPUT = 0x04
    WRITE_SINGLE = 0x06
    WRITE_MULTIPLE = 0x10


FUNCTIONS: Final = frozenset(Function)


@dataclass(slots=True, frozen=True, kw_only=True)
class ReadRequest:
    """Read ``count`` holding (FC 3) or input (FC 4) registers from ``start``."""

    address: int
    function: Function
    start: int
    count: int


@dataclass(slots=True, frozen=True, kw_only=True)
class WriteSingle:
    """Write one holding register (FC 6); the server's answer is the same frame."""

    address: int
    register: int
    value: int


@dataclass(slots=True, frozen=True, kw_only=True)
class WriteMultiple:
    """Write ``values`` to consecutive holding registers from ``start`` (FC 16)."""

    address: int
    start: int
    values: tuple[int, ...]


@dataclass(slots=True, frozen=True, kw_only=True)
class Registers:
    """The answer to a read: the registers' values, in order."""

    address: int
    function: Function
    values: tuple[int, ...]


@dataclass(slots=True, frozen=True, kw_only=True)
class Written:
    """The answer to FC 16: which span was written."""

    address: int
    start: int
    count: int


@dataclass(slots=True, frozen=True, kw_only=True)
class ExceptionReply:
    """The server could not carry the request out: its function and the exception code."""

    address: int
    function: int  # the request's function code (without the exception bit)
    code: int


Request = ReadRequest | WriteSingle | WriteMultiple
Response = Registers | WriteSingle | Written | ExceptionReply


def reply_length(request: Request) -> int:
    """Bytes of the normal answer to ``request`` (0 for a broadcast: none comes)."""
    if request.address == BROADCAST:
        return 0
    if isinstance(request, ReadRequest):
        return 5 + 2 * request.count
    return WRITE_REPLY_LENGTH


# ------------------------------------------------------------------------------ encoding


def encode_request(request: Request) -> bytes:
    """The frame of ``request``; UsageError for what the specification does not allow."""
    address = request.address
    if address != BROADCAST and address not in ADDRESSES:
        raise UsageError(f"address {address} is outside 0-247")
    match request:
        case ReadRequest(function=function, start=start, count=count):
            if address == BROADCAST:
                raise UsageError("a read cannot be broadcast: no server answers address 0")
            if function not in (Function.READ_HOLDING, Function.READ_INPUT):
                raise UsageError(f"function {function} does not read registers")
            _check_span(start, count, MAX_READ)
            body = struct.pack(">BBHH", address, function, start, count)
        case WriteSingle(register=register, value=value):
            _check_word("register", register)
            _check_word("value", value)
            body = struct.pack(">BBHH", address, Function.WRITE_SINGLE, register, value)
        case WriteMultiple(start=start, values=values):
            _check_span(start, len(values), MAX_WRITE)
            for value in values:
                _check_word("value", value)
            count = len(values)
            body = struct.pack(
                f">BBHHB{count}H", address, Function.WRITE_MULTIPLE, start, count, 2 * count,
                *values,
            )  # fmt: skip
    return with_crc(body)


def encode_response(response: Response) -> bytes:
    """The frame a server sends for ``response``."""
    if response.address not in ADDRESSES:
        raise UsageError(f"a server answers from 1-247, not {response.address}")
    match response:
        case Registers(function=function, values=values):
            if not 1 <= len(values) <= MAX_READ:
                raise UsageError(f"a read answers 1-{MAX_READ} registers, not {len(values)}")
            for value in values:
                _check_word("value", value)
            count = len(values)
            body = struct.pack(f">BBB{count}H", response.address, function, 2 * count, *values)
        case WriteSingle():
            return encode_request(response)
        case Written(start=start, count=count):
            _check_span(start, count, MAX_WRITE)
            body = struct.pack(">BBHH", response.address, Function.WRITE_MULTIPLE, start, count)
        case ExceptionReply(function=function, code=code):
            if not 1 <= function < EXCEPTION_BIT or not 0 <= code <= 0xFF:
                raise UsageError(f"no exception answer for function {function}, code {code}")
            body = bytes((response.address, function | EXCEPTION_BIT, code))
    return with_crc(body)


def _check_word(what: str, value: int) -> None:
    if not 0 <= value <= 0xFFFF:
        raise UsageError(f"{what} {value} does not fit a 16-bit register (0-65535)")


def _check_span(start: int, count: int, most: int) -> None:
    _check_word("start register", start)
    if not 1 <= count <= most:
        raise UsageError(f"{count} registers: one request takes 1-{most}")
    if start + count > 0x10000:
        raise UsageError(f"registers {start}+{count} run past 65535")


# ------------------------------------------------------------------------------ decoding


def decode_request(frame: bytes) -> Request:
    """The request in ``frame`` (a server's side); MalformedReply if it is not one."""
    _check_frame(frame)
    address, function = frame[0], frame[1]
    data = frame[2:-2]
    if function in (Function.READ_HOLDING, Function.READ_INPUT, Function.WRITE_SINGLE):
        if len(data) != 4:
            raise MalformedReply(f"function {function} takes 4 data bytes", raw=frame)
        first, second = _WORDS.unpack(data)
        if function == Function.WRITE_SINGLE:
            return WriteSingle(address=address, register=first, value=second)
        return ReadRequest(address=address, function=Function(function), start=first, count=second)
    if function == Function.WRITE_MULTIPLE:
        if len(data) < 5:
            raise MalformedReply("function 16 needs start, count and byte count", raw=frame)
        start, count, size = struct.unpack_from(">HHB", data)
        if size != 2 * count or len(data) != 5 + size:
            raise MalformedReply("function 16's count and byte count disagree", raw=frame)
        values = struct.unpack_from(f">{count}H", data, 5)
        return WriteMultiple(address=address, start=start, values=values)
    raise MalformedReply(f"function {function} is not a register function", raw=frame)


def decode_response(frame: bytes) -> Response:
    """The response in ``frame`` (the master's side); MalformedReply if it is not one."""
    _check_frame(frame)
    address, function = frame[0], frame[1]
    data = frame[2:-2]
    if function & EXCEPTION_BIT:
        if len(data) != 1:
            raise MalformedReply("an exception answer holds one code byte", raw=frame)
        return ExceptionReply(address=address, function=function & 0x7F, code=data[0])
    if function in (Function.READ_HOLDING, Function.READ_INPUT):
        if not data or data[0] != len(data) - 1 or data[0] % 2:
            raise MalformedReply("a read answer's byte count disagrees with its data", raw=frame)
        values = struct.unpack_from(f">{data[0] // 2}H", data, 1)
        return Registers(address=address, function=Function(function), values=values)
    if function in (Function.WRITE_SINGLE, Function.WRITE_MULTIPLE):
        if len(data) != 4:
            raise MalformedReply(f"the answer to function {function} has 4 data bytes", raw=frame)
        first, second = _WORDS.unpack(data)
        if function == Function.WRITE_SINGLE:
            return WriteSingle(address=address, register=first, value=second)
        return Written(address=address, start=first, count=second)
    raise MalformedReply(f"function {function} is not a register function", raw=frame)


def _check_frame(frame: bytes) -> None:
    if len(frame) < 4:
        raise MalformedReply(f"{len(frame)} bytes are too short for a frame", raw=frame)
    if not crc_ok(frame):
        raise MalformedReply("CRC does not match", raw=frame)
