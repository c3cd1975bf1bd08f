"""Modbus TCP framing and the four register functions, sans-I/O.

A Modbus TCP frame is a 7-byte MBAP header — transaction id (echoed), protocol id (0),
length (of what follows: the unit id and the PDU), unit id — then the PDU: a function code
and its data (Modbus Application Protocol V1.1b3 §4, Messaging on TCP/IP V1.0b §3.1).
This module cuts a byte stream into requests and builds the answers; it knows nothing of
sockets, drives or time.

:class:`MbapFramer` is fed whatever the socket delivered and yields one item at a time:
a :class:`Request` (a whole frame, its PDU parsed), a :class:`Refusal` (a whole frame whose
PDU is wrong: answered with an exception, the stream stays in step), or a :class:`Broken`
(a header no Modbus client sends — protocol id not 0, a length outside 2-254: the stream can
no longer be trusted and the connection is closed). Buffering is bounded by the largest
frame (260 bytes), so no client can grow memory.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass

HEADER = struct.Struct(">HHHB")  # transaction, protocol, length, unit
MAX_PDU = 253
MAX_READ = 125  # registers in one read (FC 3/4)
MAX_WRITE = 123  # registers in one write (FC 16)


class Function(enum.IntEnum):
    """The function codes served; others are answered ILLEGAL_FUNCTION."""

    READ_HOLDING = 3
    READ_INPUT = 4
    WRITE_SINGLE = 6
    WRITE_MULTIPLE = 16


class ExceptionCode(enum.IntEnum):
    """Modbus exception codes (Application Protocol §7)."""

    ILLEGAL_FUNCTION = 0x01
    ILLEGAL_DATA_ADDRESS = 0x02
    ILLEGAL_DATA_VALUE = 0x03
    SERVER_DEVICE_FAILURE = 0x04
    GATEWAY_PATH_UNAVAILABLE = 0x0A
    GATEWAY_TARGET_FAILED = 0x0B


@dataclass(slots=True, frozen=True, kw_only=True)
class Request:
    """A well-formed request for one of the four functions."""

    transaction: int
    unit: int
    function: Function
    address: int
    count: int  # registers read or written
    values: tuple[int, ...] = ()  # written registers (FC 6: one)


@dataclass(slots=True, frozen=True, kw_only=True)
class Refusal:
    """A whole frame that gets an exception instead of an answer."""

    transaction: int
    unit: int
    function: int
    code: ExceptionCode
    reason: str


@dataclass(slots=True, frozen=True)
class Broken:
    """A header that is not Modbus TCP: close the connection."""

    reason: str
    data: bytes


class MbapFramer:
    """Cuts a TCP byte stream into Modbus requests (see the module docstring)."""

    def __init__(self) -> None:
        self._buffer = b""
        self._broken = False

    @property
    def pending(self) -> int:
        """Bytes of an incomplete frame held (a half frame, waiting for its rest)."""
        return len(self._buffer)

    def feed(self, data: bytes) -> None:
        """Add bytes as they arrived."""
        if not self._broken:
            self._buffer += data

    def next_item(self) -> Request | Refusal | Broken | None:
        """The next whole frame, or None when more bytes are needed."""
        if self._broken or len(self._buffer) < HEADER.size:
            return None
        transaction, protocol, length, unit = HEADER.unpack_from(self._buffer)
        if protocol != 0 or not 2 <= length <= MAX_PDU + 1:
            self._broken = True
            data, self._buffer = self._buffer, b""
            what = f"protocol id {protocol}" if protocol else f"length {length}"
            return Broken(f"not a Modbus TCP header ({what})", data)
        end = HEADER.size - 1 + length
        if len(self._buffer) < end:
            return None
        pdu, self._buffer = self._buffer[HEADER.size : end], self._buffer[end:]
        return parse_pdu(transaction, unit, pdu)


def parse_pdu(transaction: int, unit: int, pdu: bytes) -> Request | Refusal:
    """A request from a PDU, or the exception it must get."""
    function = pdu[0]

    def refuse(code: ExceptionCode, reason: str) -> Refusal:
        return Refusal(
            transaction=transaction, unit=unit, function=function, code=code, reason=reason
        )

    try:
        fn = Function(function)
    except ValueError:
        return refuse(ExceptionCode.ILLEGAL_FUNCTION, f"function {function} is not served")
    data = pdu[1:]
    if fn in (Function.READ_HOLDING, Function.READ_INPUT, Function.WRITE_SINGLE):
        if len(data) != 4:
            return refuse(ExceptionCode.ILLEGAL_DATA_VALUE, f"function {function} takes 4 bytes")
        address, word = struct.unpack(">HH", data)
        if fn is Function.WRITE_SINGLE:
            return Request(
                transaction=transaction, unit=unit, function=fn, address=address, count=1,
                values=(word,),
            )  # fmt: skip
        if not 1 <= word <= MAX_READ:
            return refuse(ExceptionCode.ILLEGAL_DATA_VALUE, f"a read takes 1-{MAX_READ} registers")
        return Request(transaction=transaction, unit=unit, function=fn, address=address, count=word)
    if len(data) < 5:
        return refuse(ExceptionCode.ILLEGAL_DATA_VALUE, "function 16 needs address, count, bytes")
    address, count, size = struct.unpack_from(">HHB", data)
    if not 1 <= count <= MAX_WRITE or size != 2 * count or len(data) != 5 + size:
        return refuse(ExceptionCode.ILLEGAL_DATA_VALUE, "function 16's count and bytes disagree")
    values = struct.unpack_from(f">{count}H", data, 5)
    return Request(
        transaction=transaction, unit=unit, function=fn, address=address, count=count,
        values=values,
    )  # fmt: skip


def _frame(transaction: int, unit: int, pdu: bytes) -> bytes:
    return HEADER.pack(transaction, 0, len(pdu) + 1, unit) + pdu


def encode_registers(request: Request, registers: list[int]) -> bytes:
    """The answer to a read: the registers' values."""
    body = struct.pack(f">BB{len(registers)}H", request.function, 2 * len(registers), *registers)
    return _frame(request.transaction, request.unit, body)


def encode_written(request: Request) -> bytes:
    """The answer to a write that was carried out (FC 6 echoes, FC 16 confirms the span)."""
    if request.function is Function.WRITE_SINGLE:
        body = struct.pack(">BHH", request.function, request.address, request.values[0])
    else:
        body = struct.pack(">BHH", request.function, request.address, request.count)
    return _frame(request.transaction, request.unit, body)


def encode_exception(transaction: int, unit: int, function: int, code: ExceptionCode) -> bytes:
    """An exception answer: the function code with its high bit set, then the code."""
    return _frame(transaction, unit, bytes(((function | 0x80) & 0xFF, code)))
