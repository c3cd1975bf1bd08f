"""Steady polling: the idle polls and probes of a line carried out in callbacks.

Most of a line's life is polls, one after another, with nothing else to do. Carried by the
BusMaster's task, each costs two wake-ups of the task (the reply, the end of the pause),
each with its future, timer and pass of the event loop, and code that runs right after a
wake-up runs several times slower than warm code. Here the same steps are chained in
callbacks instead: when the reply's last byte arrives, the transport's reader callback
hands it over (:meth:`~fcmaster.bus.link.Link.watch`), and right there the reply is
decoded and accounted for, the planner chooses the next step, and its request is written
by a timer at the end of the pause (the clock's ``call_at``, which never ends a pause
early). No task wakes and no future is made until something else is to
be done.

The rules are the master's, applied by the same code: :class:`SteadyPolling` calls the
planner and the master's own bookkeeping exactly as the task's loop does, and gives the
line back to that loop (the awaited :meth:`SteadyPolling.run` returns) as soon as the next
step is anything but a poll or a probe: a command (it goes first: one that comes in during
a pause is seen when the pause ends, and the poll chosen before it is not sent), nothing
to do (the loop waits for a command or a probe's time), a broadcast. What a callback
raises, or the port's loss, is raised by :meth:`SteadyPolling.run`, so the master's
supervision sees it as it would in its loop.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from fcmaster.bus.link import Link
from fcmaster.bus.planner import Planner, Step, StepKind
from fcmaster.bus.stats import Histogram
from fcmaster.clock import Cancellable, Clock
from fcmaster.protocol.codec import Reply


class SteadyPolling:
    """Carries polls and probes in callbacks until a step of another kind is due."""

    def __init__(
        self,
        planner: Planner,
        link: Link,
        clock: Clock,
        *,
        sent: Callable[[Step], None],
        replied: Callable[[Step, Reply], None],
        failed: Callable[[Step], None],
        lateness: Histogram | None = None,
    ) -> None:
        self._planner = planner
        self._link = link
        self._clock = clock
        self._sent, self._replied, self._failed = sent, replied, failed
        self._step: Step | None = None  # the step peeked and not yet done
        self._timer: Cancellable | None = None
        self._lateness = lateness  # how late the pause's timer fired
        self._ended: asyncio.Future[None] | None = None

    @staticmethod
    def carries(step: Step) -> bool:
        """Whether ``step`` is one this carries (a poll or probe that expects a reply)."""
        return step.kind is not StepKind.COMMAND and step.exchange.expects_reply

    async def run(self, step: Step) -> None:
        """Carry out ``step`` (just peeked: see :meth:`carries`) and the polls after it.

        Returns when the next step is of another kind, not yet committed: the caller peeks
        again. Raises what the line raised.
        """
        ended = self._ended = asyncio.get_running_loop().create_future()
        self._step = step
        self._due()
        try:
            await ended
        finally:
            self._ended = None
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            self._link.unwatch()

    def _due(self) -> None:
        """The peeked step may go now, or at the end of the pause.

        What is left of a pause shorter than a wake-up's lateness is spun here (no turn of
        the loop for it); a longer one ends in a timer.
        """
        ready_at = self._link.ready_at
        if ready_at > self._clock.now() and not self._clock.wait_briefly(ready_at):
            self._timer = self._clock.call_at(ready_at, self._go)
        else:
            self._go()

    def _go(self) -> None:
        """The pause is over: send the peeked step, unless a command came in meanwhile."""
        if self._timer is not None and self._lateness is not None:  # the timer fired
            self._lateness.observe(self._clock.now() - self._link.ready_at)
        self._timer = None
        step, ended = self._step, self._ended
        if step is None or ended is None or ended.done():
            return
        planner, link = self._planner, self._link
        if not planner.still_next(step):
            # A command came in: it goes first, and the loop peeks again. Not merely "commands
            # are queued": one waiting for a restarting drive leaves the others' polls to go,
            # and ending here would hand the line to the loop, which peeks this poll again
            # and comes straight back without a turn of the event loop, until that drive hears.
            self._end(None)
            return
        try:
            planner.commit(step, self._clock.now())
            link.send_now(step.exchange)
            self._sent(step)
            link.watch(step.exchange, link.reply_deadline(step.exchange), self._answered)
        except Exception as exc:  # the loop's supervision decides
            self._end(exc)

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
            nxt = self._planner.peek(self._clock.now())
        except Exception as exc:  # the loop's supervision decides
            self._end(exc)
            return
        if nxt is None or not self.carries(nxt):
            self._end(None)
            return
        self._step = nxt
        self._due()

    def _end(self, error: Exception | None) -> None:
        self._step = None
        ended = self._ended
        if ended is not None and not ended.done():
            if error is None:
                ended.set_result(None)
            else:
                ended.set_exception(error)
