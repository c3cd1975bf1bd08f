"""Test doubles passed in through constructors: virtual clocks and a scripted line."""

from __future__ import annotations

import asyncio
import heapq
import itertools
from bisect import insort
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import TypeVar

from fcmaster.clock import Clock, MonotonicClock
from fcmaster.errors import PortError, ReplyTimeout

T = TypeVar("T")
EPOCH = 1_790_000_000.0  # the virtual clocks' wall clock at their time 0 (2026-09-21)


class WallShiftedClock(MonotonicClock):
    """The real clock, with a wall clock a test chooses: ``wall()`` is ``read_wall()``."""

    def __init__(self, read_wall: Callable[[], float]) -> None:
        super().__init__()
        self._read_wall = read_wall

    def wall(self) -> float:
        return self._read_wall()


class FakeClock:
    """Virtual time: a sleep moves time forward at once, then yields to other tasks.

    Good for one sleeping task. When several tasks sleep at once, use :class:`VirtualClock`,
    which wakes them in deadline order. Its wall clock moves with it: ``epoch + time``.
    """

    def __init__(self, start: float = 1000.0, *, epoch: float = EPOCH) -> None:
        self.time = start
        self.epoch = epoch

    def now(self) -> float:
        return self.time

    def wall(self) -> float:
        return self.epoch + self.time

    async def sleep(self, seconds: float) -> None:
        await self.sleep_until(self.time + seconds)

    async def sleep_until(self, deadline: float) -> None:
        if deadline > self.time:
            self.time = deadline
        await asyncio.sleep(0)


class VirtualClock:
    """Virtual time that moves only when the test runs it; sleepers wake in deadline order.

    :meth:`run_until` lets every task settle (run until it waits again), wakes the earliest
    sleeper with the time set to its deadline, and repeats, so several tasks can sleep at
    once and each sees exactly the time it asked for. Nothing sleeps in real time. Its wall
    clock moves with it: ``epoch + time``.
    """

    SETTLE_ROUNDS = 20  # event-loop turns a woken task needs to reach its next wait

    def __init__(self, start: float = 1000.0, *, epoch: float = EPOCH) -> None:
        self.time = start
        self.epoch = epoch
        self._sleepers: list[tuple[float, int, asyncio.Future[None]]] = []
        self._order = itertools.count()

    def now(self) -> float:
        return self.time

    def wall(self) -> float:
        return self.epoch + self.time

    async def sleep(self, seconds: float) -> None:
        await self.sleep_until(self.time + seconds)

    async def sleep_until(self, deadline: float) -> None:
        if deadline <= self.time:
            await asyncio.sleep(0)
            return
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        heapq.heappush(self._sleepers, (deadline, next(self._order), future))
        await future

    def next_deadline(self) -> float | None:
        """When the earliest sleeper wakes; None when nothing sleeps on this clock."""
        while self._sleepers and self._sleepers[0][2].done():  # cancelled sleepers
            heapq.heappop(self._sleepers)
        return self._sleepers[0][0] if self._sleepers else None

    async def settle(self) -> None:
        """Let every runnable task run until it waits again."""
        for _ in range(self.SETTLE_ROUNDS):
            await asyncio.sleep(0)

    async def _wake_next(self) -> None:
        deadline, _, future = heapq.heappop(self._sleepers)
        self.time = max(self.time, deadline)
        future.set_result(None)
        await self.settle()

    async def run_until(self, when: float) -> None:
        """Run every task through virtual time up to ``when``; the clock then reads ``when``."""
        await self.settle()
        while (deadline := self.next_deadline()) is not None and deadline <= when:
            await self._wake_next()
        self.time = max(self.time, when)
        await self.settle()

    async def run_for(self, seconds: float) -> None:
        """Run every task through the next ``seconds`` of virtual time."""
        await self.run_until(self.time + seconds)

    async def complete(self, awaitable: Awaitable[T], *, within: float = 60.0) -> T:
        """Run virtual time until ``awaitable`` is done (at most ``within`` seconds); its result.

        The clock stops at the moment it is done, not later.
        """
        task = asyncio.ensure_future(awaitable)
        limit = self.time + within
        await self.settle()
        while not task.done():
            deadline = self.next_deadline()
            if deadline is None or deadline > limit:
                task.cancel()
                await asyncio.gather(task, return_exceptions=True)
                raise AssertionError(f"not done within {within} s of virtual time")
            await self._wake_next()
        return task.result()


@dataclass(slots=True, frozen=True)
class Timed:
    """A reply that arrives in pieces: ``(seconds after the request was written, bytes)``."""

    pieces: tuple[tuple[float, bytes], ...]


Responder = Callable[[bytes], bytes | Timed | None]


@dataclass
class Sent:
    """One request as the line saw it."""

    at: float
    data: bytes
    reply_at: float | None = None  # when the last byte of its reply arrives; None: no reply
    deadline: float | None = None  # the latest a read for its reply waited until


@dataclass
class ScriptedTransport:
    """A line whose replies come from ``responder``, timed like a real wire.

    A reply given as bytes arrives, whole, ``delay_s`` plus the wire time of request and
    reply after the write; a :class:`Timed` reply arrives in the pieces and at the times it
    names. ``inject`` queues raw bytes that arrive now (noise, a late reply): the next read
    returns them, or the next ``discard_input`` drops them. The transport checks the
    half-duplex rule itself: a write while a reply is still due fails.
    """

    clock: Clock
    responder: Responder
    char_s: float = 11 / 19200
    delay_s: float = 0.010
    sent: list[Sent] = field(default_factory=list)
    opened: int = 0
    closed: int = 0
    open_attempts: list[float] = field(default_factory=list)
    fail_open: bool = False
    open_error: Exception | None = None  # raised by the next open (a port driver's bug)
    read_error: Exception | None = None  # raised by the next read
    lost: bool = False  # the port is gone: writes and reads raise PortError
    received_at: float = 0.0  # when the last bytes read arrived
    _arrivals: list[tuple[float, bytes]] = field(default_factory=list)  # sorted by time
    _reply_until: float = float("-inf")

    async def open(self) -> None:
        self.open_attempts.append(self.clock.now())
        if self.open_error is not None:
            error, self.open_error = self.open_error, None
            raise error
        if self.fail_open:
            raise PortError("scripted open failure")
        self.opened += 1
        self.lost = False

    async def close(self) -> None:
        self.closed += 1
        self._arrivals.clear()
        self._reply_until = float("-inf")

    async def write(self, data: bytes) -> None:
        if self.lost:
            raise PortError("scripted line loss")
        now = self.clock.now()
        assert self._reply_until <= now, "write while a reply is due"
        sent = Sent(now, data)
        self.sent.append(sent)
        reply = self.responder(data)
        if reply is None:
            return
        if isinstance(reply, Timed):
            pieces = [(now + offset, chunk) for offset, chunk in reply.pieces]
        else:
            pieces = [(now + (len(data) + len(reply)) * self.char_s + self.delay_s, reply)]
        for piece in pieces:
            insort(self._arrivals, piece)
        sent.reply_at = max(at for at, _ in pieces)
        self._reply_until = max(self._reply_until, sent.reply_at)

    async def read(self, deadline: float) -> bytes:
        if self.sent:
            last = self.sent[-1]
            last.deadline = deadline if last.deadline is None else max(last.deadline, deadline)
        if self.read_error is not None:
            error, self.read_error = self.read_error, None
            raise error
        if self.lost:
            raise PortError("scripted line loss")
        if self._arrivals and self._arrivals[0][0] <= deadline:
            await self.clock.sleep_until(self._arrivals[0][0])
            if self.lost:
                raise PortError("scripted line loss")
            return self._take_arrived()
        await self.clock.sleep_until(deadline)
        if self.lost:
            raise PortError("scripted line loss")
        raise ReplyTimeout("scripted timeout")

    def discard_input(self) -> bytes:
        return self._take_arrived()

    def inject(self, data: bytes) -> None:
        insort(self._arrivals, (self.clock.now(), data))

    def _take_arrived(self) -> bytes:
        now = self.clock.now()
        count = 0
        while count < len(self._arrivals) and self._arrivals[count][0] <= now:
            count += 1
        arrived = b"".join(chunk for _, chunk in self._arrivals[:count])
        if count:
            self.received_at = self._arrivals[count - 1][0]
        del self._arrivals[:count]
        return arrived
