"""The line's one driver: every step of a line carried out in callbacks.

A line's life is exchanges one after another: a request written when the pause after the
last reply is over, its reply read as it arrives, the next step chosen. Carried by a task,
each exchange would cost two wake-ups of it (the reply, the end of the pause), each with
its future, timer and pass of the event loop. Here they are chained in callbacks instead:
when the reply's last byte arrives, the transport's reader callback hands it over
(:meth:`~fcmaster.bus.link.Link.watch`), and right there the reply is decoded and accounted
for, the planner chooses the next step, and its request is written by a timer at the end
of the pause (the clock's ``call_at``, which never ends a pause early). No task wakes and
no future is made.

Every kind of step goes this way — polls, probes, commands, broadcasts — on every transport
a line runs on (a serial port, the simulator's line, the virtual-time tests' scripted line),
so the path a real port runs all day is the one the tests run. With nothing to do, the
runner waits for the planner's next wake-up (a probe falling due) or for :meth:`wake` (a
command or a new plan came in).

The rules live in the planner and are applied at the step's last moment: a step chosen
before the pause is sent only if it is still next when the pause ends
(:meth:`~fcmaster.bus.planner.Planner.still_next`). A command that came in meanwhile goes
first, a command cancelled at shutdown or superseded by a stop is never sent, and a line
whose plan is being changed is changed between two exchanges (``between``), never while one
is on the wire. What a callback raises, and the port's loss, end :meth:`LineRunner.run` with
that exception, so the master's supervision sees it.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from fcmaster.bus.link import Link
from fcmaster.bus.planner import Planner, Step, StepKind
from fcmaster.bus.stats import Histogram
from fcmaster.clock import Cancellable, Clock
from fcmaster.protocol.codec import Reply


class LineRunner:
    """Carries a line's steps in callbacks until the line fails."""

    def __init__(
        self,
        planner: Planner,
        link: Link,
        clock: Clock,
        *,
        between: Callable[[], None],
        idle: Callable[[], None],
        sent: Callable[[Step], None],
        replied: Callable[[Step, Reply], None],
        failed: Callable[[Step], None],
        broadcast: Callable[[Step], None],
        lateness: Histogram | None = None,
    ) -> None:
        self._planner = planner
        self._link = link
        self._clock = clock
        self._between, self._idle = between, idle
        self._sent, self._replied, self._failed = sent, replied, failed
        self._broadcast = broadcast
        self._lateness = lateness  # how late the pause's timer fired
        self._step: Step | None = None  # the step peeked and not yet sent
        self._timer: Cancellable | None = None  # the end of the pause, or the idle wake-up
        self._idling = False
        self._ended: asyncio.Future[None] | None = None

    async def run(self) -> None:
        """Carry out the line's steps; returns only by raising what ended the line."""
        ended = self._ended = asyncio.get_running_loop().create_future()
        try:
            self._next()
            await ended
        finally:
            self._ended = None
            self._step = None
            self._idling = False
            self._cancel_timer()
            self._link.unwatch()

    def wake(self) -> None:
        """Something came in (a command, a new plan): choose again if the line is idle.

        A step waiting out its pause needs no wake: it asks whether it is still next when
        the pause ends. One on the wire chooses the next when its reply comes.
        """
        if self._idling and self._ended is not None:
            self._cancel_timer()
            self._next()

    # -- the chain ----------------------------------------------------------------------

    def _next(self) -> None:
        """Between two exchanges: choose the next step and wait for its time, or idle."""
        self._idling = False
        self._step = None
        try:
            self._between()
            now = self._clock.now()
            step = self._planner.peek(now)
            if step is None:
                self._idle()
                wakeup = self._planner.next_wakeup(now)
                self._idling = True
                if wakeup is not None:
                    self._timer = self._clock.call_at(wakeup, self._woken)
                return
        except Exception as exc:  # the master's supervision decides
            self._end(exc)
            return
        self._step = step
        ready_at = self._link.ready_at
        # What is left of a pause shorter than a wake-up's lateness is spun here (no turn of
        # the loop for it); a longer one ends in a timer.
        if ready_at > self._clock.now() and not self._clock.wait_briefly(ready_at):
            self._timer = self._clock.call_at(ready_at, self._paused)
        else:
            self._go()

    def _woken(self) -> None:
        """The planner's wake-up came (a probe falls due) with nothing else to do."""
        self._timer = None
        if self._idling and self._ended is not None:
            self._next()

    def _paused(self) -> None:
        """The pause's timer fired."""
        self._timer = None
        if self._lateness is not None:
            self._lateness.observe(self._clock.now() - self._link.ready_at)
        self._go()

    def _go(self) -> None:
        """The pause is over: send the peeked step, unless it is no longer the next."""
        step, ended = self._step, self._ended
        if step is None or ended is None or ended.done():
            return
        planner, link = self._planner, self._link
        if not planner.still_next(step):
            # A command came in (it may go first, or supersede or replace this one), this
            # one ended (cancelled at shutdown), or the plan is being changed: choose again.
            self._next()
            return
        exchange = step.exchange
        try:
            planner.commit(step, self._clock.now())
            link.send_now(exchange)
            self._sent(step)
            if not exchange.expects_reply:
                self._broadcast(step)
            else:
                # Commands wait the plan's fixed deadline: see Link.
                adaptive = step.kind is not StepKind.COMMAND
                deadline = link.reply_deadline(exchange, adaptive=adaptive)
                link.watch(exchange, deadline, self._answered)
                return
        except Exception as exc:  # the master's supervision decides
            self._end(exc)
            return
        self._next()

    def _answered(self, reply: Reply | None, error: Exception | None) -> None:
        """The step's reply came, or its deadline passed: account, and choose the next."""
        step, ended = self._step, self._ended
        if step is None or ended is None or ended.done():
            return
        if error is not None:
            self._end(error)
            return
        try:
            self._link.received(step.exchange, reply)
            if reply is None:
                self._failed(step)
            else:
                self._replied(step, reply)
        except Exception as exc:  # the master's supervision decides
            self._end(exc)
            return
        self._next()

    def _cancel_timer(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _end(self, error: Exception) -> None:
        self._step = None
        ended = self._ended
        if ended is not None and not ended.done():
            ended.set_exception(error)
