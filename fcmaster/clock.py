"""Time, injected: the :class:`Clock` seam and the event loop that keeps sub-millisecond time.

Everything that waits (the bus master's pauses and deadlines, the simulator's wire delays,
reconnect backoff) or stamps a time (the fleet state's ``updated_at``, MQTT events, register
ages) takes a Clock, so tests run in virtual time and the same code runs on a real port. The
service makes one and hands it to the lines, the fleet state and every adapter.

Why a special event loop: at 115200 baud two characters last 0.19 ms, but asyncio's default
loop on Linux waits in epoll, whose timeout is whole milliseconds, so every short sleep
ends up to 1 ms late — a third more line time per transaction. A loop on ``select()``
(microsecond timeouts) with the thread's timer slack lowered from 50 µs to 1 µs wakes within
a few tens of microseconds instead (on a busy VM, a few hundred), and
:class:`MonotonicClock` takes out what remains by waking early and spinning the last
stretch. select() handles file descriptors below 1024, which a gateway with a handful of
ports and connections stays far below.

Unlike epoll, select() fails whole (EBADF) when one registered descriptor was closed behind
the loop's back, and the loop would die with it. A library that registers from another
thread can do that: aiomqtt schedules its ``add_reader`` with ``call_soon_threadsafe``, so a
connection that fails at once has its socket closed before the registration runs. The
selector here drops such descriptors (the loop's own ``remove_reader`` then finds nothing, as
it allows) and selects again.
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import ctypes.util
import errno
import os
import selectors
import sys
import time
from collections.abc import Callable
from typing import ClassVar, Protocol

_PR_SET_TIMERSLACK = 29


class Cancellable(Protocol):
    """A scheduled call that can be called off."""

    def cancel(self) -> None:
        """Do not make the call (a no-op once it was made)."""


class Clock(Protocol):
    """Monotonic time in float seconds, and waiting on it: by a task, or by a callback.

    The callbacks are what a line's runner is made of (:mod:`fcmaster.bus.runner`, the
    transports' receivers): a virtual clock calls them in virtual time exactly as the real
    one calls them on the event loop, so the path a real port runs is the path the
    virtual-time tests run.
    """

    def now(self) -> float:
        """Seconds on a monotonic clock."""

    def wall(self) -> float:
        """Seconds since the Unix epoch, for the times people read (RFC 3339); never to wait on."""

    async def sleep(self, seconds: float) -> None:
        """Wait ``seconds``."""

    async def sleep_until(self, deadline: float) -> None:
        """Wait until ``now() >= deadline``."""

    def call_at(self, deadline: float, callback: Callable[[], None]) -> Cancellable:
        """Call ``callback`` at ``deadline``, never before it, as precisely as the clock can."""

    def timer_at(self, deadline: float, callback: Callable[[], None]) -> Cancellable:
        """Call ``callback`` at ``deadline`` or a little after (a deadline's plain timer).

        Not spun to the microsecond like :meth:`call_at`: for reply deadlines and
        inter-character gaps, where a wake-up's lateness costs nothing.
        """

    def wait_briefly(self, deadline: float) -> bool:
        """Spin until ``deadline`` if it is nearer than a wake-up would come; whether it did.

        A clock that never spins says False at once, and the caller uses :meth:`call_at`.
        """


class MonotonicClock:
    """The real clock; the same timebase as the running event loop's ``loop.time()``.

    The kernel wakes a sleeper late, by an amount that depends on the machine (tens of
    microseconds on bare metal under the precise loop, a few hundred in a busy VM), so the
    clock learns how late its wake-ups come (a running average), asks to be woken that
    much sooner, and spins through the rest. Spinning holds the event loop and burns CPU,
    so the lead is capped (``max_lead_s``): by default a wait spins at most :attr:`SPIN_S`
    (0.1 ms); a simulator, whose job is to keep time and whose CPU is nobody's budget, may
    allow more. Only the stretch the clock expects the kernel to be late by is spun: a wait
    longer than that sleeps first, however short (a spin of the whole 0.1 ms costs more CPU
    than the wake-up it saves), and a wait that has already passed returns at once, without
    a turn of the loop. Only waits shorter than :attr:`LEARN_BELOW_S` teach the
    clock: the kernel lets a long wait run late by a share of its length (0.1 %), and a
    reconnect backoff of seconds needs no microseconds anyway.

    A long wait is split: the kernel wakes a long sleep later than a short one (in a VM,
    about 0.27 ms after 10 ms against 0.09 ms after 1 ms), more than the lead may cover,
    so a wait longer than :attr:`SPLIT_S` first sleeps to within a margin of its end (1 ms,
    or 1 % of a long wait) and the short learned sleep lands it on the deadline. It costs
    one more wake-up, not a longer spin: a Mitsubishi line's 10 ms turnaround and a
    simulated drive's 5 ms answer delay end on time.
    """

    __slots__ = ("_early", "max_lead_s")

    SPIN_S: ClassVar[float] = 0.0001
    SPLIT_S: ClassVar[float] = 0.002
    LEARN_BELOW_S: ClassVar[float] = 0.05
    _LEARNING_RATE: ClassVar[float] = 0.125

    def __init__(self, *, max_lead_s: float = SPIN_S) -> None:
        self.max_lead_s = max_lead_s
        self._early = 0.0  # how much sooner than the deadline to ask to be woken

    # Seconds on the monotonic clock: the C function itself, as it is read several times a
    # transaction (a method around it would add a Python call each time).
    now = staticmethod(time.monotonic)

    # The wall clock is ``time.time`` itself, not a method around it: the fleet state stamps
    # every reply with it, and a call through a Python method would cost more than the read.
    wall = staticmethod(time.time)

    async def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` on the event loop."""
        await self.sleep_until(time.monotonic() + seconds)

    async def sleep_until(self, deadline: float) -> None:
        """Wait until ``deadline``; return at once if it has passed."""
        early = self._early
        wake_at = deadline - early
        delay = wake_at - time.monotonic()
        if delay > self.SPLIT_S:
            await asyncio.sleep(delay - max(0.001, delay * 0.01))
            delay = wake_at - time.monotonic()
        if delay > 0:  # longer than the kernel's expected lateness: sleep, then spin the rest
            await asyncio.sleep(delay)
            if delay < self.LEARN_BELOW_S:
                late = min(time.monotonic() - wake_at, self.max_lead_s)
                self._early = early + (late - early) * self._LEARNING_RATE
        while time.monotonic() < deadline:
            pass  # the last stretch, shorter than a wake-up's usual lateness

    def wait_briefly(self, deadline: float) -> bool:
        """Spin until ``deadline`` if it is nearer than a wake-up would come; whether it did.

        A wait shorter than the clock's expected lateness would be spun anyway after a turn
        of the loop (see :meth:`call_at`); a callback chain can spin it right here instead,
        with no turn of the loop and no timer. False (at once, having waited nothing): the
        wait is longer, and the caller schedules the call with :meth:`call_at`.
        """
        if deadline - time.monotonic() > self._early:
            return False
        while time.monotonic() < deadline:
            pass  # shorter than a wake-up's usual lateness
        return True

    def call_at(self, deadline: float, callback: Callable[[], None]) -> Timer:
        """Call ``callback`` on the running loop at ``deadline``, never before it.

        :meth:`sleep_until` for a callback, with the same lead, spin and split of a long
        wait, but no task wakes and no future is made. ``cancel()`` on what it returns calls
        it off.
        """
        holder = Timer()
        self._arm(holder, deadline, callback)
        return holder

    def timer_at(self, deadline: float, callback: Callable[[], None]) -> asyncio.TimerHandle:
        """A plain timer on the running loop for ``deadline`` (see :meth:`Clock.timer_at`)."""
        return asyncio.get_running_loop().call_later(deadline - self.now(), callback)

    def _arm(self, holder: Timer, deadline: float, callback: Callable[[], None]) -> None:
        loop = asyncio.get_running_loop()
        wake_at = deadline - self._early
        delay = wake_at - time.monotonic()
        if delay > self.SPLIT_S:
            holder.handle = loop.call_later(
                delay - max(0.001, delay * 0.01), self._arm, holder, deadline, callback
            )
        elif delay > 0:
            holder.handle = loop.call_later(delay, self._fire, wake_at, delay, deadline, callback)
        else:
            holder.handle = loop.call_soon(self._fire, wake_at, 0.0, deadline, callback)

    def _fire(
        self, wake_at: float, delay: float, deadline: float, callback: Callable[[], None]
    ) -> None:
        if 0 < delay < self.LEARN_BELOW_S:
            early = self._early
            late = min(time.monotonic() - wake_at, self.max_lead_s)
            self._early = early + (late - early) * self._LEARNING_RATE
        while time.monotonic() < deadline:
            pass  # the last stretch, shorter than a wake-up's usual lateness
        callback()


class Timer:
    """A callback :meth:`MonotonicClock.call_at` will call; ``cancel()`` calls it off."""

    __slots__ = ("handle",)

    def __init__(self) -> None:
        self.handle: asyncio.Handle | None = None

    def cancel(self) -> None:
        """Do not call it (a no-op once it was called)."""
        if self.handle is not None:
            self.handle.cancel()


def lower_timer_slack() -> bool:
    """Ask Linux to wake this thread's timers within 1 µs; return whether it agreed."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        return int(libc.prctl(_PR_SET_TIMERSLACK, 1, 0, 0, 0)) == 0
    except (OSError, AttributeError):
        return False


class ClosedFdSafeSelector(selectors.SelectSelector):
    """select() that outlives a descriptor closed while registered (see the module docstring)."""

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        """Ready keys, as SelectSelector's; a closed descriptor is unregistered first."""
        try:
            return super().select(timeout)
        except OSError as exc:
            if exc.errno != errno.EBADF:
                raise
        for key in list(self.get_map().values()):
            try:
                os.fstat(key.fd)
            except OSError:
                with contextlib.suppress(KeyError, ValueError):
                    self.unregister(key.fileobj)
        return super().select(0)


def new_event_loop() -> asyncio.AbstractEventLoop:
    """An event loop whose timers keep sub-millisecond time (see the module docstring)."""
    lower_timer_slack()
    return asyncio.SelectorEventLoop(ClosedFdSafeSelector())
