"""Test doubles passed in through constructors: a virtual clock and a scripted line."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass, field

from fcmaster.errors import ReplyTimeout


class FakeClock:
    """Virtual time: a sleep moves time forward at once, then yields to other tasks."""

    def __init__(self, start: float = 1000.0) -> None:
        self.time = start

    def now(self) -> float:
        return self.time

    async def sleep(self, seconds: float) -> None:
        await self.sleep_until(self.time + seconds)

    async def sleep_until(self, deadline: float) -> None:
        if deadline > self.time:
            self.time = deadline
        await asyncio.sleep(0)


Responder = Callable[[bytes], bytes | None]


@dataclass
class Sent:
    """One request as the line saw it."""

    at: float
    data: bytes


@dataclass
class ScriptedTransport:
    """A line whose replies come from ``responder``, timed like a real wire.

    A reply arrives ``delay_s`` plus the wire time of request and reply after the write.
    ``inject`` queues raw bytes that arrive before the next reply (noise, a late reply).
    It checks the half-duplex rule itself: a write while a reply is still due fails.
    """

    clock: FakeClock
    responder: Responder
    char_s: float = 11 / 19200
    delay_s: float = 0.010
    sent: list[Sent] = field(default_factory=list)
    opened: int = 0
    fail_open: bool = False
    lost: bool = False
    _reply: bytes | None = None
    _reply_at: float = 0.0
    _stale: bytearray = field(default_factory=bytearray)

    async def open(self) -> None:
        if self.fail_open:
            from fcmaster.errors import PortError

            raise PortError("scripted open failure")
        self.opened += 1
        self.lost = False

    async def close(self) -> None:
        self._reply = None

    async def write(self, data: bytes) -> None:
        if self.lost:
            from fcmaster.errors import PortError

            raise PortError("scripted line loss")
        now = self.clock.now()
        assert self._reply is None or self._reply_at <= now, "write while a reply is due"
        if self._reply is not None:  # never read: it is stale input now
            self._stale += self._reply
        self.sent.append(Sent(now, data))
        reply = self.responder(data)
        self._reply = reply
        if reply is not None:
            self._reply_at = now + (len(data) + len(reply)) * self.char_s + self.delay_s

    async def read(self, deadline: float) -> bytes:
        if self._stale:
            data = bytes(self._stale)
            self._stale.clear()
            return data
        if self._reply is not None and self._reply_at <= deadline:
            await self.clock.sleep_until(self._reply_at)
            reply, self._reply = self._reply, None
            return reply
        await self.clock.sleep_until(deadline)
        raise ReplyTimeout("scripted timeout")

    def discard_input(self) -> bytes:
        data = bytes(self._stale)
        self._stale.clear()
        if self._reply is not None and self._reply_at <= self.clock.now():
            data += self._reply
            self._reply = None
        return data

    def inject(self, data: bytes) -> None:
        self._stale += data
