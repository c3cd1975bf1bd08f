"""A small Modbus TCP client written from the specification, for the adapter's tests.

It shares no code with the server (:mod:`fcmaster.adapters.modbus_frames`), so a mistake
in one is not mirrored in the other; ``mbpoll`` (a C client) checks the server a second,
independent way. Register values are plain ints; 32-bit helpers join high word first.
"""

from __future__ import annotations

import asyncio
import math
import shutil
import struct
from types import TracebackType

import pytest


class ModbusError(Exception):
    """The server answered with an exception code."""

    def __init__(self, function: int, code: int) -> None:
        super().__init__(f"function {function}: exception 0x{code:02X}")
        self.function = function
        self.code = code


class Client:
    """One connection; requests one at a time, each with its own transaction id."""

    def __init__(self, host: str, port: int, *, timeout_s: float = 10.0) -> None:
        self.host = host
        self.port = port
        self.timeout_s = timeout_s
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._transaction = 0

    async def __aenter__(self) -> Client:
        self._reader, self._writer = await asyncio.open_connection(self.host, self.port)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._writer is not None:
            self._writer.close()

    async def send_raw(self, data: bytes) -> None:
        """Put bytes on the connection as they are."""
        assert self._writer is not None
        self._writer.write(data)
        await self._writer.drain()

    async def receive_frame(self) -> tuple[int, int, bytes]:
        """The next answer: transaction id, unit id and PDU."""
        assert self._reader is not None
        async with asyncio.timeout(self.timeout_s):
            header = await self._reader.readexactly(7)
            transaction, protocol, length, unit = struct.unpack(">HHHB", header)
            assert protocol == 0, header.hex(" ")
            pdu = await self._reader.readexactly(length - 1)
        return transaction, unit, pdu

    async def closed_by_server(self) -> bool:
        """Whether the server closes the connection, answering nothing (bounded wait).

        A socket closed with our bytes unread resets the connection, and one closed while we
        were still sending breaks our pipe: those are closed too.
        """
        assert self._reader is not None
        try:
            async with asyncio.timeout(self.timeout_s):
                return await self._reader.read(1024) == b""
        except (ConnectionResetError, BrokenPipeError):
            return True

    async def request(self, unit: int, pdu: bytes) -> bytes:
        """Send one PDU to ``unit``; the answer's PDU, or ModbusError for an exception."""
        self._transaction = (self._transaction + 1) & 0xFFFF
        sent = self._transaction
        await self.send_raw(struct.pack(">HHHB", sent, 0, len(pdu) + 1, unit) + pdu)
        transaction, answered_unit, answer = await self.receive_frame()
        assert (transaction, answered_unit) == (sent, unit)
        if answer[0] == pdu[0] | 0x80:
            raise ModbusError(pdu[0], answer[1])
        assert answer[0] == pdu[0], answer.hex(" ")
        return answer

    async def read_input(self, unit: int, address: int, count: int) -> list[int]:
        """FC 4."""
        return await self._read(4, unit, address, count)

    async def read_holding(self, unit: int, address: int, count: int) -> list[int]:
        """FC 3."""
        return await self._read(3, unit, address, count)

    async def _read(self, function: int, unit: int, address: int, count: int) -> list[int]:
        answer = await self.request(unit, struct.pack(">BHH", function, address, count))
        assert answer[1] == 2 * count == len(answer) - 2
        return list(struct.unpack(f">{count}H", answer[2:]))

    async def write_single(self, unit: int, address: int, value: int) -> None:
        """FC 6; the answer must echo the request."""
        pdu = struct.pack(">BHH", 6, address, value)
        assert await self.request(unit, pdu) == pdu

    async def write_multiple(self, unit: int, address: int, values: list[int]) -> None:
        """FC 16; the answer must confirm address and count."""
        count = len(values)
        pdu = struct.pack(f">BHHB{count}H", 16, address, count, 2 * count, *values)
        assert await self.request(unit, pdu) == struct.pack(">BHH", 16, address, count)


def f32(words: list[int]) -> float:
    """Two registers, high word first, as an IEEE 754 single."""
    return float(struct.unpack(">f", struct.pack(">HH", *words))[0])


def i32(words: list[int]) -> int:
    """Two registers, high word first, as a signed 32-bit integer."""
    return int(struct.unpack(">i", struct.pack(">HH", *words))[0])


def is_nan(words: list[int]) -> bool:
    """Whether two registers hold a float NaN."""
    return math.isnan(f32(words))


def mbpoll() -> str:
    """The path of ``mbpoll``; fails the test when it is not installed."""
    path = shutil.which("mbpoll")
    if path is None:
        pytest.fail("mbpoll is not installed (apt-get install mbpoll; .ci/run does it)")
    return path
