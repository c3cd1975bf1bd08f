"""The watchdog audit: whether each commanded drive stops by itself if the gateway dies.

Theory of operation
-------------------
A ``control: bus`` drive is fed a control word in every exchange, so its own communication
watchdog (FC 8-03/8-04, Mitsubishi Pr.122 or Pr.336, ENC F2.16) is what stops the motor
when the gateway dies. Each time such a drive comes online (first adoption, after a
demotion, after the line was down: it may have been replaced meanwhile),
:class:`WatchdogAudit` reads those parameters through the line's ordinary command queue —
reads like any other, served between polls, so polling keeps its pace — and judges the
setting against the line's worst-case poll round (:func:`~fcmaster.bus.poll_round.poll_round_s`):

* ``ok`` — the drive stops (ramp or trip) once it hears nothing for longer than a round,
  and a gateway restart does not trip it: its timeout covers the restart gap
  (``restart_gap_s``: from the daemon's start until its first telegram to the drive, which
  the drive answered then or, powered off meanwhile, later) and a round after it (the first
  telegram of an adopted drive marks its control word not valid; the valid one follows
  within a round);
* ``off`` — it keeps running if the gateway dies (watchdog off, or an action such as
  FC's freeze output that leaves the motor turning);
* ``too_short`` — the timeout is shorter than a round, so normal polling trips it
  (Mitsubishi Pr.122 = 0 counts so: it trips as soon as the link commands), or shorter than
  the restart gap and a round, so a gateway restart trips it;
* ``unknown`` — the reads failed, or the setting's effect cannot be told (FC's set-up
  switch).

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
import enum
import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Final

import structlog

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.bus.master import BusObserver
from fcmaster.bus.plan import DrivePlan, LinePlan, WatchdogPlan
from fcmaster.bus.poll_round import poll_round_s
from fcmaster.bus.stats import LineStats
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

ACTOR: Final = "watchdog-audit"  # the audit line's actor for the reads and writes
# A timeout worth suggesting leaves room for retries, commands and probes between two
# polls of a drive: this many worst-case rounds, and never under a second.
SUGGESTED_ROUNDS: Final = 4
SUGGESTED_MIN_S: Final = 1.0
AUDIT_SHARE: Final = 0.1  # the most of the line's time the audit's exchanges take
AUDIT_REST_MAX_S: Final = 10.0  # the longest rest after one exchange (one that timed out)

Execute = Callable[[str, Command], Awaitable[CommandResult]]


class Verdict(enum.StrEnum):
    """What a drive's watchdog does for a dead gateway (DESIGN.md "Drive state")."""

    OK = "ok"
    OFF = "off"
    TOO_SHORT = "too_short"
    UNKNOWN = "unknown"


@dataclass(slots=True, frozen=True)
class WatchdogReport:
    """A drive's watchdog as last read, and the verdict on it.

    ``restart_gap_s`` is what the daemon's start cost the drive (None: not measured); it is
    context for the verdict, not part of what the drive reported, so it does not take part
    in comparisons.
    """

    timeout_s: float | None
    action: str
    verdict: Verdict
    restart_gap_s: float | None = field(default=None, compare=False)

    def to_json(self) -> dict[str, Any]:
        """``{"timeout_s", "action", "verdict"}``, and ``restart_gap_s`` once measured."""
        out: dict[str, Any] = {
            "timeout_s": self.timeout_s,
            "action": self.action,
            "verdict": self.verdict.value,
        }
        if self.restart_gap_s is not None:
            out["restart_gap_s"] = self.restart_gap_s
        return out


def judge(setting: WatchdogSetting, round_s: float, restart_gap_s: float = 0.0) -> Verdict:
    """The verdict on ``setting`` for a line whose worst-case poll round is ``round_s``.

    ``restart_gap_s``: how long the daemon's start took to reach the drive; a timeout that
    does not cover it and a round after it (the first valid control word) trips the drive at
    every gateway restart.
    """
    if setting.stops is False or setting.timeout_s is None:
        return Verdict.OFF
    if setting.stops is None:
        return Verdict.UNKNOWN
    if setting.timeout_s < restart_gap_s + round_s:
        return Verdict.TOO_SHORT
    return Verdict.OK


def suggested_timeout_s(round_s: float) -> float:
    """A timeout to advise for a line whose worst-case poll round is ``round_s`` (0.1 s steps)."""
    return max(SUGGESTED_MIN_S, math.ceil(round_s * SUGGESTED_ROUNDS * 10 - 1e-9) / 10)


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
        self._turn = asyncio.Lock()  # one audit exchange at a time on the line
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
        self._execute = execute
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
        values, problem = await self._read(drive, facts)
        if values is None and problem is None:
            return  # the line went down or shut: the next time online audits again
        wanted = drive.watchdog
        if wanted is not None:
            writes = facts.encode(wanted.timeout_s, wanted.action)
            if values is None or not _matches(facts, values, writes):
                written = await self._write(drive, wanted, writes)
                if written is None:
                    return
                values, problem = await self._read(drive, facts)
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
            written = await self._write(drive, wanted, writes)
            if written is None:
                return
            if written is Outcome.REFUSED:  # its setting is as last reported: no new verdict
                run_first = True  # at most once per stop: next after a run and a stop
                continue
            values, problem = await self._read(drive, facts)
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

    async def _exchange(self, name: str, command: Command) -> CommandResult:
        """Carry out ``command``, then rest, keeping the audit to its share of the line."""
        assert self._execute is not None
        async with self._turn:
            started = self._clock.now()
            result = await self._execute(name, command)
            spent = self._clock.now() - started
            rest = spent * (1.0 - AUDIT_SHARE) / AUDIT_SHARE
            await self._clock.sleep(min(rest, AUDIT_REST_MAX_S))
        return result

    async def _read(
        self, drive: DrivePlan, facts: WatchdogFacts
    ) -> tuple[list[float] | None, str | None]:
        """The watchdog parameters' values; else None and why (None too: line gone)."""
        values: list[float] = []
        for parameter in facts.parameters:
            command = Command(action=Action.READ, parameter=parameter, actor=ACTOR, internal=True)
            result = await self._exchange(drive.name, command)
            if result.outcome is Outcome.CANCELLED or (
                not result.ok and drive.name in self._offline
            ):
                return None, None  # the line or the drive is gone: its return audits again
            value = result.value
            if result.outcome is not Outcome.DONE or value is None:
                return None, f"{parameter} could not be read ({result.outcome.value}: " + (
                    f"{result.reason})" if result.reason else "no value)"
                )
            if isinstance(value.value, str):
                return None, f"{parameter} read as text {value.value!r}, not a number"
            values.append(float(value.value))
        return values, None

    async def _write(
        self, drive: DrivePlan, wanted: WatchdogPlan, writes: tuple[tuple[str, float], ...]
    ) -> Outcome | None:
        """Write the configured setting: DONE, or the first write's failure (None: line gone)."""
        for parameter, value in writes:
            command = Command(
                action=Action.WRITE, parameter=parameter, value=value, persist=True, actor=ACTOR
            )
            result = await self._exchange(drive.name, command)
            if result.outcome is Outcome.CANCELLED or (
                not result.ok and drive.name in self._offline
            ):
                return None
            if result.outcome is not Outcome.DONE:
                self._log.warning(
                    "drive.watchdog_write_failed",
                    drive=drive.name,
                    param=parameter,
                    value=value,
                    outcome=result.outcome.value,
                    reason=result.reason or None,
                    wanted_timeout_s=wanted.timeout_s,
                    wanted_action=wanted.action,
                    retry="once the drive is seen stopped"
                    if result.outcome is Outcome.REFUSED
                    else None,
                )
                return result.outcome
        self._log.info(
            "drive.watchdog_written",
            drive=drive.name,
            timeout_s=wanted.timeout_s,
            action=wanted.action,
        )
        return Outcome.DONE

    def _finish(
        self, drive: DrivePlan, setting: WatchdogSetting | None, problem: str | None
    ) -> None:
        """Report the verdict, and log it: ``off`` and ``too_short`` as warnings, with the fix."""
        gap = self.restart_gaps.get(drive.name)
        if setting is None:
            report = WatchdogReport(None, "unknown", Verdict.UNKNOWN, gap)
            self._log.info("drive.watchdog_unknown", drive=drive.name, reason=problem)
            self._warned.pop(drive.name, None)
            self._report(self.plan.name, drive.name, report)
            return
        verdict = judge(setting, self.round_s, gap or 0.0)
        report = WatchdogReport(setting.timeout_s, setting.action, verdict, gap)
        facts = self._facts(drive)
        round_s = round(self.round_s, 4)
        # with room for a restart like this one: twice its gap
        suggested = max(suggested_timeout_s(self.round_s), math.ceil((gap or 0.0) * 20) / 10)
        fix = facts.advice(suggested)
        if drive.watchdog is None:
            fix += f", or configure the drive with watchdog: {{timeout_s: {suggested:g}}}"
        fields: dict[str, Any] = {
            "drive": drive.name,
            "address": drive.address,
            "timeout_s": setting.timeout_s,
            "action": setting.action,
            "poll_round_s": round_s,
            "restart_gap_s": None if gap is None else round(gap, 3),
        }
        if self._warned.get(drive.name) == report:
            # The same again (a drive that comes and goes): said once, not at every return.
            self._log.info("drive.watchdog_unchanged", **fields, verdict=verdict.value)
        elif verdict is Verdict.OFF:
            self._log.warning(
                "drive.watchdog_off",
                **fields,
                consequence="the motor keeps running if the gateway dies",
                fix=fix,
            )
        elif verdict is Verdict.TOO_SHORT:
            restart = setting.timeout_s is not None and setting.timeout_s >= self.round_s
            self._log.warning(
                "drive.watchdog_too_short",
                **fields,
                consequence=(
                    "a gateway restart trips the drive"
                    if restart
                    else "normal polling can trip the drive"
                ),
                fix=fix,
            )
        elif verdict is Verdict.UNKNOWN:
            self._log.info(
                "drive.watchdog_unknown",
                **fields,
                reason=f"what {setting.action!r} does cannot be told from the parameters",
            )
        else:
            self._log.info("drive.watchdog_checked", **fields, verdict=verdict.value)
        if verdict in (Verdict.OFF, Verdict.TOO_SHORT):
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


def _matches(
    facts: WatchdogFacts, values: list[float], writes: tuple[tuple[str, float], ...]
) -> bool:
    """Whether the values read already hold what ``writes`` would write."""
    read = dict(zip(facts.parameters, values, strict=True))
    return all(
        parameter in read and math.isclose(read[parameter], value, abs_tol=1e-6)
        for parameter, value in writes
    )
