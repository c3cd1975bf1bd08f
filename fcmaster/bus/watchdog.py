"""The watchdog audit: whether each commanded drive stops by itself if the gateway dies.

Theory of operation
-------------------
A ``control: bus`` drive is fed a control word in every exchange, so its own communication
watchdog (FC 8-03/8-04, Mitsubishi Pr.122 or Pr.336, ENC F2.16) is what stops the motor
when the gateway dies. Each time such a drive comes online (first adoption, after a
demotion, after the line was down: it may have been replaced meanwhile),
:class:`WatchdogAudit` reads those parameters through the line's ordinary command queue —
reads like any other, served between polls, so polling keeps its pace — and judges the
setting against the line's worst-case poll round (:func:`~fcmaster.bus.poll_round.poll_round_s`)
and what the daemon's restart cost the drive: ``ok``, ``off``, ``too_short`` or ``unknown``
(:mod:`~fcmaster.bus.watchdog_verdict`).

The audit's exchanges go through the queue one at a time for the whole line, and each is
followed by a rest nine times as long as it took (``AUDIT_SHARE``), so the audit takes at
most a tenth of the line's time however many drives come online together: a line of 126
drives coming up is audited over a minute or so, while every drive keeps being polled
(and its watchdog fed) at nearly its full rate. The reads are the gateway's own
housekeeping, like the ramp reads, so they make no audit line; the verdict's log line
carries what they read. ``off`` and ``too_short`` are logged as warnings with the fix in
words, once per drive: the same again when the drive returns is logged at info. A read
that fails because the drive went offline judges nothing; its return audits it again.

A drive configured with ``watchdog: {timeout_s, action}`` whose setting differs is
written (timeout first) and read back; the verdict is always that of what the drive
reports, never of what was asked. A drive that already has the setting is not written, so
a gateway that restarts often does not wear the drive's memory. A write the drive refuses
(Mitsubishi and ENC drives refuse parameter writes while running) is tried again once the
drive is seen stopped: at most once per stop, so a drive that keeps refusing is asked again
only after it has run and stopped anew. Only while such a retry waits does the audit look at
the drive's replies (its status word); otherwise replies never pass through it.

The vendor facts live in each protocol package's ``watchdog`` module, and reach the audit
through the protocol's spec (``ProtocolSpec.watchdog_of`` the line: Mitsubishi's depend on
the port the drives are wired to).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from functools import partial

import structlog

from fcmaster.bus.commands import Outcome
from fcmaster.bus.master import BusObserver
from fcmaster.bus.plan import DrivePlan, LinePlan, WatchdogPlan
from fcmaster.bus.poll_round import poll_round_s
from fcmaster.bus.stats import LineStats
from fcmaster.bus.watchdog_access import AuditAccess, Execute, matches
from fcmaster.bus.watchdog_verdict import (
    Verdict,
    WatchdogReport,
    judge,
    say,
    suggested_timeout_s,
)
from fcmaster.clock import Clock
from fcmaster.protocol.codec import Reply
from fcmaster.protocol.drive import ControlIntent
from fcmaster.protocol.registry import spec_for
from fcmaster.protocol.watchdog import WatchdogFacts, WatchdogSetting

__all__ = [
    "Verdict",
    "WatchdogAudit",
    "WatchdogReport",
    "judge",
    "suggested_timeout_s",
]

log = structlog.get_logger("fcmaster.bus")


class WatchdogAudit:
    """Reads, judges and (where configured) writes the watchdogs of one line's drives.

    ``report(bus, drive, report)`` receives each verdict. :meth:`observing` wraps the line's
    observer so that a drive coming online starts its audit; :meth:`attach` gives the
    audit the line's command path once the BusMaster exists.
    """

    def __init__(
        self,
        plan: LinePlan,
        *,
        clock: Clock,
        report: Callable[[str, str, WatchdogReport], None],
        started_at: float | None = None,
    ) -> None:
        self.plan = plan
        self._clock = clock
        # the daemon's start (default: now); each drive's first telegram since, less this
        self.started_at = clock.now() if started_at is None else started_at
        self.restart_gaps: dict[str, float] = {}
        # drives a reload added: the gap runs from then, not from the daemon's start
        self._taken_at: dict[str, float] = {}
        self._stats: LineStats | None = None
        self.facts = spec_for(plan.protocol).watchdog_of(plan)  # Mitsubishi: by drive_port
        self.round_s = poll_round_s(plan)[0] if plan.drives else 0.0
        self._report = report
        self._execute: Execute | None = None
        self._tasks: dict[str, asyncio.Task[None]] = {}
        self._stopped = False
        self._log = log.bind(bus=plan.name)
        self._observer: _AuditingObserver | None = None
        self._warned: dict[str, WatchdogReport] = {}  # the warning each drive last had
        self._offline: set[str] = set()  # drives that went offline since they last answered
        self._access = AuditAccess(clock, self._log, self._offline)
        # drives whose refused write waits for a stop: name → (the stop seen, wait for a run
        # first); while any waits, the observer shows the audit the replies
        self._stop_waits: dict[str, tuple[asyncio.Future[None], bool]] = {}

    def replan(self, plan: LinePlan) -> None:
        """The line's drives are now ``plan``'s (a reload): audits of drives it left end."""
        before = {drive.name for drive in self.plan.drives}
        self.plan = plan
        self.round_s = poll_round_s(plan)[0] if plan.drives else 0.0
        names = {drive.name for drive in plan.drives}
        for name in set(self._tasks) - names:
            self._tasks.pop(name).cancel()
        for name in before - names:  # one added again later is taken over anew
            self.restart_gaps.pop(name, None)
            self._taken_at.pop(name, None)
        now = self._clock.now()
        for name in names - before:
            self._taken_at[name] = now

    def attach(self, execute: Execute, stats: LineStats | None = None) -> None:
        """Send the audit's reads and writes through ``execute`` (the line's BusMaster).

        ``stats``: the line's, where the master notes its first telegram to each drive.
        """
        self._execute = self._access.execute = execute
        self._stats = stats

    def observing(self, inner: BusObserver) -> BusObserver:
        """``inner``, with this audit told when a drive comes online."""
        self._observer = _AuditingObserver(inner, self)
        return self._observer

    def drive_online(self, drive: DrivePlan, at: float | None = None) -> None:
        """``drive`` answers again (at ``at``): audit it (again), ending one under way."""
        if at is not None and drive.name not in self.restart_gaps:
            # The daemon's first telegram to the drive: a drive that answers only later was
            # not there (powered off), and its watchdog was not running meanwhile.
            counters = None if self._stats is None else self._stats.drives.get(drive.name)
            first = None if counters is None else counters.first_request_at
            since = self._taken_at.get(drive.name, self.started_at)
            self.restart_gaps[drive.name] = max(0.0, (at if first is None else first) - since)
        self._offline.discard(drive.name)
        if not drive.control or self._execute is None or self._stopped:
            return
        running = self._tasks.pop(drive.name, None)
        if running is not None:
            running.cancel()
        task = asyncio.create_task(
            self._audit(drive), name=f"bus[{self.plan.name}].watchdog[{drive.name}]"
        )
        self._tasks[drive.name] = task
        task.add_done_callback(partial(self._done, drive.name))

    def drive_offline(self, drive: DrivePlan) -> None:
        """``drive`` stopped answering: what its audit then fails to read judges nothing.

        Reads that failed because the drive lost power are no verdict on its watchdog, so
        the verdict it had stays until the drive answers again and is audited anew.
        """
        self._offline.add(drive.name)

    def stop(self) -> None:
        """Shutdown begins: nothing more goes out for the audit, whatever comes online."""
        self._stopped = True
        for task in self._tasks.values():
            task.cancel()

    async def aclose(self) -> None:
        """End every audit under way (shutdown)."""
        self._stopped = True
        tasks = list(self._tasks.values())
        self._tasks.clear()
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)

    def _done(self, name: str, task: asyncio.Task[None]) -> None:
        if self._tasks.get(name) is task:
            del self._tasks[name]
        if not task.cancelled() and task.exception() is not None:
            exc = task.exception()
            self._log.error("drive.watchdog_audit_failed", drive=name, error=repr(exc))

    # -- one drive -------------------------------------------------------------------------

    def _facts(self, drive: DrivePlan) -> WatchdogFacts:
        """The drive's own facts where its profile has them (modbus-rtu), else the line's."""
        return spec_for(self.plan.protocol).drive_watchdog(self.plan, drive.profile)

    async def _audit(self, drive: DrivePlan) -> None:
        facts = self._facts(drive)
        if facts is None:  # pragma: no cover - every protocol has its facts
            self._finish(drive, None, f"no watchdog facts for {self.plan.protocol}")
            return
        if not facts.parameters:
            # Nothing to read (a Modbus drive whose profile names no watchdog registers):
            # whether the motor stops when the gateway dies is not known, which is not "off".
            self._finish(drive, None, "no watchdog parameters are known for this drive")
            return
        values, problem = await self._access.read(drive, facts)
        if values is None and problem is None:
            return  # the line went down or shut: the next time online audits again
        wanted = drive.watchdog
        if wanted is not None:
            writes = facts.encode(wanted.timeout_s, wanted.action)
            if values is None or not matches(facts, values, writes):
                written = await self._access.write(drive, wanted, writes)
                if written is None:
                    return
                values, problem = await self._access.read(drive, facts)
                if values is None and problem is None:
                    return
                if written is Outcome.REFUSED:
                    self._verdict(drive, facts, values, problem)  # what it has meanwhile
                    await self._retry_when_stopped(drive, wanted, writes)
                    return
        self._verdict(drive, facts, values, problem)

    def _verdict(
        self,
        drive: DrivePlan,
        facts: WatchdogFacts,
        values: list[float] | None,
        problem: str | None,
    ) -> None:
        if values is None:
            self._finish(drive, None, problem)
        else:
            self._finish(drive, facts.decode(values), None)

    async def _retry_when_stopped(
        self, drive: DrivePlan, wanted: WatchdogPlan, writes: tuple[tuple[str, float], ...]
    ) -> None:
        """Write again once the drive is seen stopped; again refused: after its next stop."""
        facts = self._facts(drive)
        assert facts is not None
        run_first = False  # the first retry: at the first stopped status, even if it is now
        while True:
            await self._seen_stopped(drive.name, run_first=run_first)
            self._log.info(
                "drive.watchdog_write_retried",
                drive=drive.name,
                reason="the drive refused the write, and is now seen stopped",
                wanted_timeout_s=wanted.timeout_s,
                wanted_action=wanted.action,
            )
            written = await self._access.write(drive, wanted, writes)
            if written is None:
                return
            if written is Outcome.REFUSED:  # its setting is as last reported: no new verdict
                run_first = True  # at most once per stop: next after a run and a stop
                continue
            values, problem = await self._access.read(drive, facts)
            if values is not None or problem is not None:
                self._verdict(drive, facts, values, problem)
            return

    async def _seen_stopped(self, name: str, *, run_first: bool) -> None:
        """Until a reply of ``name`` shows it stopped (after one showing it running)."""
        seen: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._stop_waits[name] = (seen, run_first)
        self._watch_replies()
        try:
            await seen
        finally:  # seen, or the audit ended (shutdown, the drive came online again)
            if self._stop_waits.get(name, (None,))[0] is seen:
                del self._stop_waits[name]
            self._watch_replies()

    def _watch_replies(self) -> None:
        """Let the replies through the audit only while a retry waits for a stop."""
        if self._observer is not None:
            self._observer.watch(bool(self._stop_waits))

    def drive_replied(self, drive: DrivePlan, reply: Reply) -> None:
        """A reply while retries wait: a drive seen stopped gets its write again."""
        wait = self._stop_waits.get(drive.name)
        status = reply.status
        if wait is None or status is None:
            return
        seen, run_first = wait
        if status.running:
            if run_first:
                self._stop_waits[drive.name] = (seen, False)
        elif not run_first and not seen.done():
            seen.set_result(None)

    def _finish(
        self, drive: DrivePlan, setting: WatchdogSetting | None, problem: str | None
    ) -> None:
        """Report the verdict, and log it: ``off`` and ``too_short`` as warnings, with the fix."""
        gap = self.restart_gaps.get(drive.name)
        if setting is None:
            report = WatchdogReport(None, "unknown", Verdict.UNKNOWN, gap)
            self._log.info("drive.watchdog_unknown", drive=drive.name, reason=problem)
        else:
            report = WatchdogReport(
                setting.timeout_s, setting.action, judge(setting, self.round_s, gap or 0.0), gap
            )
            said_before = self._warned.get(drive.name) == report
            say(self._log, drive, self._facts(drive), report, self.round_s, again=said_before)
        if report.verdict in (Verdict.OFF, Verdict.TOO_SHORT):
            self._warned[drive.name] = report
        else:
            self._warned.pop(drive.name, None)
        self._report(self.plan.name, drive.name, report)


class _AuditingObserver:
    """A line's observer, with the audit told of drives coming online.

    Only availability goes through here; the other calls are the inner observer's own
    bound methods, so a reply costs nothing more than before — except while a refused write
    waits for its drive to stop (:meth:`watch`), when replies pass the audit too.
    """

    def __init__(self, inner: BusObserver, audit: WatchdogAudit) -> None:
        self._inner = inner
        self._audit = audit
        self.drive_replied: Callable[..., None] = inner.drive_replied
        self.line_availability = inner.line_availability
        self.command_completed = inner.command_completed

    def watch(self, on: bool) -> None:
        """Show the audit each reply (``on``), or only the inner observer (the usual)."""
        self.drive_replied = self._replied_watched if on else self._inner.drive_replied

    def _replied_watched(
        self, bus: str, drive: DrivePlan, reply: Reply, at: float, commanded: ControlIntent | None
    ) -> None:
        self._inner.drive_replied(bus, drive, reply, at, commanded)
        self._audit.drive_replied(drive, reply)

    def drive_availability(self, bus: str, drive: DrivePlan, online: bool, at: float) -> None:
        """Pass it on; a drive that came online is audited, one that went offline is not."""
        self._inner.drive_availability(bus, drive, online, at)
        if online:
            self._audit.drive_online(drive, at)
        else:
            self._audit.drive_offline(drive)
