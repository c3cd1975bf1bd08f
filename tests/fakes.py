"""Test doubles passed in through constructors: virtual clocks and a scripted line."""

from __future__ import annotations

import asyncio
import heapq
import itertools
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from functools import partial
from typing import TypeVar

from fcmaster.clock import Cancellable, Clock, MonotonicClock
from fcmaster.errors import PortError, ReplyTimeout
from fcmaster.protocol.framing import Framer
from fcmaster.transport.receiver import Handler, Piece, Receiver
from fcmaster.transport.usb import Adapter

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

    def call_at(self, deadline: float, callback: Callable[[], None]) -> Cancellable:
        raise AssertionError(
            "FakeClock moves only when a task sleeps, so it cannot call back at a time: "
            "use VirtualClock where something schedules callbacks (a line's transport)"
        )

    timer_at = call_at

    def wait_briefly(self, deadline: float) -> bool:
        return False


class _Call:
    """A callback a virtual clock will call; ``cancel()`` calls it off."""

    __slots__ = ("_callback",)

    def __init__(self, callback: Callable[[], None]) -> None:
        self._callback: Callable[[], None] | None = callback

    def cancel(self) -> None:
        self._callback = None

    def done(self) -> bool:
        return self._callback is None

    def fire(self) -> None:
        callback, self._callback = self._callback, None
        if callback is not None:
            callback()


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
        # Sleeping tasks (a future to set) and callbacks (call_at, timer_at), by deadline.
        self._sleepers: list[tuple[float, int, asyncio.Future[None] | _Call]] = []
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

    def call_at(self, deadline: float, callback: Callable[[], None]) -> _Call:
        """Call ``callback`` when virtual time reaches ``deadline`` (in deadline order)."""
        call = _Call(callback)
        heapq.heappush(self._sleepers, (deadline, next(self._order), call))
        return call

    timer_at = call_at

    def wait_briefly(self, deadline: float) -> bool:
        return False  # virtual time never spins: the caller schedules the call

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
        deadline, _, sleeper = heapq.heappop(self._sleepers)
        self.time = max(self.time, deadline)
        if isinstance(sleeper, _Call):
            sleeper.fire()
        else:
            sleeper.set_result(None)
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
    names. ``inject`` delivers raw bytes now (noise, a late reply): the next read returns
    them, or the next ``discard_input`` drops them. The transport checks the half-duplex
    rule itself: a write while a reply is still due fails.

    The bytes arrive on the clock's timers into the serial transport's own
    :class:`~fcmaster.transport.receiver.Receiver`, and the transport has a serial port's
    callback powers (:attr:`framing`), so the master runs the path a real port runs:
    replies framed in the reader callback, polls carried in callbacks.
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
    adapter: Adapter | None = None  # the USB adapter a test puts behind the line
    _receiver: Receiver = field(init=False)
    _deliveries: list[Cancellable] = field(default_factory=list)  # arrivals still to come
    _reply_until: float = float("-inf")

    def __post_init__(self) -> None:
        self._receiver = Receiver(self.clock)

    @property
    def received_at(self) -> float:
        """When the last bytes arrived."""
        return self._receiver.received_at

    @property
    def framing(self) -> ScriptedTransport:
        return self

    async def appeared(self) -> None:
        await asyncio.Event().wait()  # a scripted line has no device node

    async def open(self) -> None:
        self.open_attempts.append(self.clock.now())
        if self.open_error is not None:
            error, self.open_error = self.open_error, None
            raise error
        if self.fail_open:
            raise PortError("scripted open failure")
        self.opened += 1
        self.lost = False
        self._receiver.lost = None

    async def close(self) -> None:
        self.closed += 1
        for delivery in self._deliveries:
            delivery.cancel()
        self._deliveries.clear()
        self._receiver.unwatch()
        self._receiver.buffer.clear()
        self._reply_until = float("-inf")

    async def write(self, data: bytes) -> None:
        self.write_now(data)

    def write_now(self, data: bytes) -> None:
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
        for at, chunk in sorted(pieces, key=lambda piece: piece[0]):
            self._deliveries.append(self.clock.timer_at(at, partial(self._arrive, chunk, at)))
        sent.reply_at = max(at for at, _ in pieces)
        self._reply_until = max(self._reply_until, sent.reply_at)

    def _arrive(self, chunk: bytes, at: float) -> None:
        if self.lost:  # the reply never comes: a reader hears of the loss now, as from a port
            self._receiver.connection_lost(PortError("scripted line loss"))
        else:
            self._receiver.arrived(chunk, at)

    def _note_deadline(self, deadline: float) -> None:
        if self.sent:
            last = self.sent[-1]
            last.deadline = deadline if last.deadline is None else max(last.deadline, deadline)

    async def read(self, deadline: float) -> bytes:
        self._note_deadline(deadline)
        if self.read_error is not None:
            error, self.read_error = self.read_error, None
            raise error
        self.check_open()
        receiver = self._receiver
        if not receiver.buffer:
            await receiver.wait_bytes(deadline)
            self.check_open()
            if not receiver.buffer:
                raise ReplyTimeout("scripted timeout")
        return self.discard_input()

    def watch_frame(self, framer: Framer, deadline: float, gap_s: float, handler: Handler) -> Piece:
        self._note_deadline(deadline)
        if self.read_error is not None:
            error, self.read_error = self.read_error, None
            raise error
        return self._receiver.watch(framer, deadline, gap_s, handler)

    def unwatch(self) -> None:
        self._receiver.unwatch()

    def check_open(self) -> None:
        if self.lost:
            raise PortError("scripted line loss")

    def discard_input(self) -> bytes:
        buffer = self._receiver.buffer
        data = bytes(buffer)
        buffer.clear()
        return data

    def inject(self, data: bytes) -> None:
        self._receiver.arrived(data, self.clock.now())
