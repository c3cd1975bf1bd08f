"""BusMaster: owns a half-duplex line, its port, its supervision and its commands.

Theory of operation
-------------------
One transaction is in flight at any time. The :class:`~fcmaster.bus.runner.LineRunner`
asks the :class:`Planner` for a step and carries it over a
:class:`~fcmaster.bus.link.Link`, which owns the wire discipline:
the pause after the previous reply, dropping stale input, one-burst writes, reading until a
frame answers the request or the deadline passes, and draining after a timeout so a late
reply is never taken for the next one.

The turnaround between a reply and the next request is the master's whole overhead, so the
runner does there only what decides the next request: decode, planner update, encode. Drive
updates for the layers above are handed on right *after* the next request is written, while
it is on the wire. Command results are resolved at once.

The pause is counted from the reply's arrival, so the work inside it is free; the clock's
sleep must be precise for this to hold (see :mod:`fcmaster.clock`). A command that arrives
during the pause still goes first: the step chosen before it is chosen again, and a command
chosen before the pause that ended meanwhile (cancelled at shutdown, superseded by a stop)
is never sent. Every step is carried in callbacks, on every transport (a serial port, the
simulator's line, the virtual-time tests' scripted line): one driver, so the path a real
port runs all day is the path the tests run. This class's task only opens the port, runs
the runner until the line fails, and reopens; what the line tells the layers above goes
through :mod:`~fcmaster.bus.reporting`.

A port that fails (adapter unplugged, server gone) takes the line down: queued commands end
``cancelled`` with the reason, and the port is reopened with jittered exponential backoff
capped at a few seconds, at once when a vanished device node appears again. Other lines
are separate BusMasters and never notice.

Nothing ends a line silently. An unexpected exception in opening the port or in the loop
(a bug, a port driver raising what it should not) is logged as ``bus.crashed`` with the
line's recent frames; the line goes down with the reason (``stats.down_reason``), its
queued commands end ``cancelled`` with it, and serving restarts after a backoff. What an
observer raises is logged (``bus.observer_failed``) and never reaches the line.
"""

from __future__ import annotations

import asyncio
import random
from functools import partial

import structlog

from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.bus.frame_log import FrameLog
from fcmaster.bus.link import Link

# BusObserver is named here too, where the layers above have always found it.
from fcmaster.bus.observer import BusObserver as BusObserver
from fcmaster.bus.observer import NullObserver
from fcmaster.bus.plan import LinePlan
from fcmaster.bus.planner import Completion, Planner, Step
from fcmaster.bus.reporting import LineReporter
from fcmaster.bus.runner import LineRunner
from fcmaster.bus.stats import DriveStats, LineStats
from fcmaster.clock import Clock
from fcmaster.errors import (
    PortError,
)
from fcmaster.protocol.codec import DriveCodec, Reply
from fcmaster.transport.pipe import Transport

log = structlog.get_logger("fcmaster.bus")

BACKOFF_FIRST_S = 0.5
BACKOFF_MAX_S = 4.0  # a line is back within seconds of its port, never half a minute


class BusMaster:
    """Polls and commands the drives of one line. Use as ``async with BusMaster(...)``."""

    def __init__(
        self,
        plan: LinePlan,
        *,
        codec: DriveCodec,
        transport: Transport,
        clock: Clock,
        observer: BusObserver | None = None,
        rng: random.Random | None = None,
        answered_before: frozenset[int] = frozenset(),
    ) -> None:
        """``answered_before``: the addresses that answered when the daemon last ran."""
        self.plan = plan
        self.codec = codec
        self.planner = Planner(plan, codec, answered_before=answered_before)
        self.stats = LineStats(drives={d.name: DriveStats() for d in plan.drives})
        self._transport = transport
        self._clock = clock
        self._link = Link(plan, codec=codec, transport=transport, clock=clock, stats=self.stats)
        # Every step runs in callbacks: see runner.py.
        self._runner = LineRunner(
            self.planner,
            self._link,
            clock,
            between=self._between,
            idle=self._idle,
            sent=self._sent,
            replied=self._replied,
            failed=self._failed,
            broadcast=self._broadcast,
            lateness=self.stats.wakeup_lateness,
        )
        self._observer: BusObserver = observer or NullObserver()
        self._rng = rng or random.Random()
        self._tried = asyncio.Event()  # the port has been tried once since __aenter__
        self._task: asyncio.Task[None] | None = None
        self._up = False
        self.stats.down_reason = "not started"
        self._closing = False
        self._serving = False  # inside _serve: the line's state changes only between exchanges
        self._replans: list[tuple[LinePlan, asyncio.Future[None]]] = []
        self._log = log.bind(bus=plan.name, port=plan.port)
        self._report = LineReporter(
            plan.name,
            planner=self.planner,
            stats=self.stats,
            observer=self._observer,
            clock=clock,
            log=self._log,
            recent_frames=self._link.recent_frames,
        )

    # -- lifecycle -----------------------------------------------------------------------

    async def __aenter__(self) -> BusMaster:
        if self._task is not None:
            raise RuntimeError("BusMaster is already running; it is not re-entrant")
        self._closing = False
        self._tried.clear()
        self._task = asyncio.create_task(self._run(), name=f"bus[{self.plan.name}].master")
        # Return once the port has been tried: a command sent right away then finds the line
        # up, or is told why it is down, instead of being cancelled as "not started".
        tried = asyncio.ensure_future(self._tried.wait())
        try:
            await asyncio.wait((tried, self._task), return_when=asyncio.FIRST_COMPLETED)
        except BaseException:
            await self.close()
            raise
        finally:
            tried.cancel()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    async def close(self) -> None:
        """Stop the loop, end every queued command as cancelled, close the port."""
        self._closing = True
        task, self._task = self._task, None
        try:
            if task is not None:
                task.cancel()
                try:
                    await task
                except asyncio.CancelledError:
                    current = asyncio.current_task()
                    if current is not None and current.cancelling():
                        raise
        finally:  # even if the loop died of a bug: every command still gets its one result
            self._up = False
            self.stats.down_reason = "shut down"
            self.planner.on_line_down()
            self._report.resolve(self.planner.cancel_all(f"{self.plan.name} shut down"))
            await self._transport.close()

    @property
    def is_up(self) -> bool:
        """Whether the port is open and the line is being served."""
        return self._up

    # -- commands ------------------------------------------------------------------------

    async def execute(self, name: str | None, command: Command) -> CommandResult:
        """Carry out ``command`` on drive ``name`` (None: broadcast); one result, always."""
        future: asyncio.Future[CommandResult] = asyncio.get_running_loop().create_future()
        if not self._up or self._closing:
            # What the config forbids is refused as such even while the line is down.
            reason = f"{self.plan.name} is down: {self.stats.down_reason}"
            refusal = self.planner.refusal(name, command) or CommandResult(
                outcome=Outcome.CANCELLED, reason=reason
            )
            self._report.resolve([Completion((future,), command, name or "*", refusal)])
        else:  # the planner refuses what the config forbids
            self._report.resolve(self.planner.submit(name, command, future))
            self._runner.wake()
        return await future

    async def reconfigure(self, plan: LinePlan) -> None:
        """Serve the drives of ``plan`` from now on, without closing the port.

        ``plan``'s line settings must be this line's (port, character format, timing): only
        its drives differ. Applied between two exchanges, never while one is on the wire,
        and the poll round goes on where it was (see :meth:`Planner.reconfigure`); returns
        once applied.
        """
        done: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._replans.append((plan, done))
        if self._serving:
            self.planner.held = True  # a step chosen before this is chosen again after it
            self._runner.wake()
        else:
            self._replan()
        await done

    def _replan(self) -> None:
        """Apply the plans :meth:`reconfigure` was given; nothing is on the wire."""
        replans, self._replans = self._replans, []
        for plan, done in replans:
            self._report.flush()  # what the drives said before, while they are all known
            names = {drive.name for drive in plan.drives}
            self._report.resolve(
                self.planner.reconfigure(plan, "the drive was removed from the configuration")
            )
            for name in set(self.stats.drives) - names:
                del self.stats.drives[name]
            for name in names:
                self.stats.drives.setdefault(name, DriveStats())
            self.plan = plan
            if not done.done():
                done.set_result(None)

    def cancel_queued(self, reason: str) -> None:
        """Shutdown: end every queued command but stops and the one on the wire, cancelled."""
        self._report.resolve(self.planner.cancel_queued(reason))

    # -- the loop ------------------------------------------------------------------------

    async def _run(self) -> None:
        """Open, serve, and when either fails, say why, end the queue and try again.

        Nothing ends this loop but :meth:`close`: a lost port is reopened soon, and an
        unexpected exception (a bug, a port driver raising what it should not) is logged as
        ``bus.crashed``, takes the line down with that reason and restarts it with backoff.
        """
        attempt = 0  # opens that failed in a row
        crashes = 0  # servings that crashed in a row
        while not self._closing:
            try:
                await self._transport.open()
            except Exception as exc:  # any failure to open is retried
                reason = str(exc) if isinstance(exc, PortError) else self._crashed("open", exc)
                self.stats.down_reason = reason
                delay = self._backoff(attempt)
                attempt += 1
                self._log.warning("bus.open_failed", error=reason, retry_in_s=round(delay, 2))
                self._tried.set()
                await self._retry_after(delay)
                continue
            attempt = 0
            now = self._clock.now()
            self._up = True
            self.stats.up_since = now
            self.stats.down_reason = None
            self._log.info("bus.opened")
            self._report.notify(self._observer.line_availability, self.plan.name, True, "", now)
            self._tried.set()
            try:
                await self._serve()
            except PortError as exc:
                self._line_lost(str(exc), f"{self.plan.name} lost its port: {exc}")
                delay = BACKOFF_FIRST_S * (0.8 + 0.4 * self._rng.random())
            except Exception as exc:  # supervised: logged, line restarted
                reason = self._crashed("serve", exc)
                self._line_lost(reason, f"{self.plan.name} stopped: {reason}")
                # A serving that lasted a while was not a crash loop: start the backoff over.
                if self._clock.now() - now > BACKOFF_MAX_S:
                    crashes = 0
                delay = self._backoff(crashes)
                crashes += 1
            await self._close_port()
            self.stats.reopens += 1
            await self._clock.sleep(delay)

    async def _retry_after(self, delay: float) -> None:
        """Wait ``delay``, or less when the port's device node appears (adapter plugged in)."""
        sleeper = asyncio.ensure_future(self._clock.sleep(delay))
        watcher = asyncio.ensure_future(self._transport.appeared())
        try:
            await asyncio.wait((sleeper, watcher), return_when=asyncio.FIRST_COMPLETED)
        finally:
            sleeper.cancel()
            watcher.cancel()
        if watcher.done() and not watcher.cancelled():
            self._log.info("bus.port_appeared")

    def _backoff(self, attempt: int) -> float:
        """Capped, jittered exponential backoff: so that many lines do not retry in step."""
        delay: float = min(BACKOFF_MAX_S, BACKOFF_FIRST_S * 2**attempt)
        return delay * (0.8 + 0.4 * self._rng.random())

    def _crashed(self, during: str, exc: Exception) -> str:
        """Log an unexpected exception with the line's recent frames; the reason to show."""
        self.stats.crashes += 1
        reason = f"internal error in {during}: {type(exc).__name__}: {exc}"
        self._log.error(
            "bus.crashed",
            during=during,
            error=f"{type(exc).__name__}: {exc}",
            recent_frames=self.recent_frames,
            exc_info=exc,
        )
        return reason

    async def _close_port(self) -> None:
        try:
            await self._transport.close()
        except Exception as exc:  # a port that fails to close is reopened
            self._log.warning("bus.close_failed", error=f"{type(exc).__name__}: {exc}")

    def _line_lost(self, reason: str, cancel_reason: str) -> None:
        self._up = False
        self.stats.down_reason = reason
        now = self._clock.now()
        self._report.flush()  # the last replies were true when they came: pass them on first
        self._log.warning("bus.lost", error=reason, recent_frames=self.recent_frames)
        self._report.resolve(self.planner.cancel_all(cancel_reason))
        self.planner.on_line_down()  # when it is back, adopt the drives as at start
        self.stats.line_silent = False
        for slot in self.planner.slots:
            if slot.online:
                slot.online = None
                self._report.notify(
                    self._observer.drive_availability, self.plan.name, slot.plan, False, now
                )
        self._report.notify(self._observer.line_availability, self.plan.name, False, reason, now)

    async def _serve(self) -> None:
        self._serving = True
        try:
            await self._runner.run()  # every step in callbacks, until the line fails
        finally:
            self._serving = False
            if self._replans:  # the line is lost or closing: nothing is on the wire now
                self._replan()

    def _between(self) -> None:
        """Between two exchanges: the plans :meth:`reconfigure` was given apply now."""
        if self._replans:
            self._replan()

    def _idle(self) -> None:
        """Nothing to send until a command or a probe's time: the layers above catch up."""
        self._report.flush()

    def _sent(self, step: Step) -> None:
        """``step``'s request is on the wire."""
        self._report.flush()  # the layers above get the last reply while this one travels
        self._report.count_request(step)

    def _replied(self, step: Step, reply: Reply) -> None:
        """``step`` got ``reply`` (the Link has accounted for it)."""
        now = self._link.replied_at
        self._report.count_reply(step, reply, now - self._link.written_at)
        self._report.handle(self.planner.on_reply(step, reply, now))
        slot = step.slot
        if slot is not None:
            replied = self._observer.drive_replied
            self._report.defer(partial(replied, self.plan.name, slot.plan, reply, now, slot.intent))

    def _broadcast(self, step: Step) -> None:
        """``step``'s request, which gets no answer, is on the wire."""
        self._report.handle(self.planner.on_sent(step, self._clock.now()))

    def _failed(self, step: Step) -> None:
        """``step`` got no valid reply before its deadline."""
        self._report.count_failure(step)
        self._report.handle(
            self.planner.on_failure(step, self._clock.now(), self._report.timeout_reason(step))
        )

    @property
    def frames(self) -> FrameLog:
        """The line's frames with their times, for captures."""
        return self._link.frames

    @property
    def recent_frames(self) -> list[str]:
        """The line's last frames and events, oldest first (the flight recorder)."""
        return self._link.recent_frames()
