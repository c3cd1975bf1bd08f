"""Time, injected: the :class:`Clock` seam and the event loop that keeps sub-millisecond time.

Everything that waits (the bus master's pauses and deadlines, the simulator's wire delays,
reconnect backoff) takes a Clock, so tests run in virtual time and the same code runs on a
real port.

Why a special event loop: at 115200 baud two characters last 0.19 ms, but asyncio's default
loop on Linux waits in epoll, whose timeout is whole milliseconds, so every short sleep
ends up to 1 ms late — a third more line time per transaction. A loop on ``select()``
(microsecond timeouts) with the thread's timer slack lowered from 50 µs to 1 µs wakes within
a few tens of microseconds instead. select() handles file descriptors below 1024, which a
gateway with a handful of ports and connections stays far below.
"""

from __future__ import annotations

import asyncio
import ctypes
import ctypes.util
import selectors
import sys
import time
from typing import Protocol

_PR_SET_TIMERSLACK = 29


class Clock(Protocol):
    """Monotonic time in float seconds, and waiting on it."""

    def now(self) -> float:
        """Seconds on a monotonic clock."""

    async def sleep(self, seconds: float) -> None:
        """Wait ``seconds``."""

    async def sleep_until(self, deadline: float) -> None:
        """Wait until ``now() >= deadline``."""


class MonotonicClock:
    """The real clock; the same timebase as the running event loop's ``loop.time()``."""

    __slots__ = ()

    def now(self) -> float:
        """Seconds on the monotonic clock."""
        return time.monotonic()

    async def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` on the event loop."""
        await self.sleep_until(time.monotonic() + seconds)

    async def sleep_until(self, deadline: float) -> None:
        """Wait until ``deadline``; return at once if it has passed.

        A long wait is split: the kernel wakes a timer late by a share of its length, so
        the first sleep ends a little early and a short second one lands on the deadline.
        """
        delay = deadline - time.monotonic()
        if delay <= 0:
            return
        margin = max(0.001, delay * 0.01)
        if delay > 2 * margin:
            await asyncio.sleep(delay - margin)
            delay = deadline - time.monotonic()
            if delay <= 0:
                return
        await asyncio.sleep(delay)


def lower_timer_slack() -> bool:
    """Ask Linux to wake this thread's timers within 1 µs; return whether it agreed."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        return int(libc.prctl(_PR_SET_TIMERSLACK, 1, 0, 0, 0)) == 0
    except (OSError, AttributeError):
        return False


def new_event_loop() -> asyncio.AbstractEventLoop:
    """An event loop whose timers keep sub-millisecond time (see the module docstring)."""
    lower_timer_slack()
    return asyncio.SelectorEventLoop(selectors.SelectSelector())
