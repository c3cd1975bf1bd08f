"""The watchdog audit in virtual time: what it reads and writes on the wire, and its verdicts.

A real BusMaster on a scripted line of tiny FC drives (``fcdrive.py``), its observer
wrapped by a :class:`WatchdogAudit`. FC 8-03 travels as a Uint32 in 0.1 s (raw 600 =
60.0 s, the FC 102 factory setting) and 8-04 as an option number ([0] Off, [2] Stop).
"""

from __future__ import annotations

import asyncio
import dataclasses
import itertools
import random
from typing import Any

import pytest
import structlog.testing

from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan, WatchdogPlan
from fcmaster.bus.poll_round import poll_round_s
from fcmaster.bus.watchdog import Verdict, WatchdogAudit, WatchdogReport, judge
from fcmaster.protocol.danfoss_fc import RequestAk, ResponseAk, decode_telegram, make_pke
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.modbus_rtu.profile import WatchdogProfile
from fcmaster.protocol.modbus_rtu.profiles import BUILT_IN
from fcmaster.protocol.watchdog import WatchdogSetting
from tests.fakes import Responder, ScriptedTransport, Timed, VirtualClock
from tests.unit.bus.bench import DELAY_S, T0, Bench, Recorder, reply_frame
from tests.unit.bus.fcdrive import FcDrive, FcLine, default_parameters

TIME, FUNCTION = 803, 804
WRITES = (
    RequestAk.WRITE_WORD,
    RequestAk.WRITE_DWORD,
    RequestAk.WRITE_WORD_EEPROM,
    RequestAk.WRITE_DWORD_EEPROM,
)


def _drive(address: int, time_raw: int, function: int, **kwargs: Any) -> FcDrive:
    parameters = default_parameters() | {TIME: time_raw, FUNCTION: function}
    return FcDrive(address, parameters=parameters, **kwargs)


def _bench(
    *drives: DrivePlan, fc: list[FcDrive], responder: Responder | None = None, **options: Any
) -> tuple[Bench, list[tuple[str, WatchdogReport]], WatchdogAudit]:
    plan = dataclasses.replace(LinePlan(name="line1", port="scripted", drives=drives), **options)
    clock = VirtualClock(T0)
    transport = ScriptedTransport(clock, responder or FcLine(*fc), delay_s=DELAY_S)
    observer = Recorder(transport=transport)
    reports: list[tuple[str, WatchdogReport]] = []
    audit = WatchdogAudit(
        plan, clock=clock, report=lambda bus, name, report: reports.append((name, report))
    )
    master = BusMaster(
        plan,
        codec=FcCodec(),
        transport=transport,
        clock=clock,
        observer=audit.observing(observer),
        rng=random.Random(1),
    )
    audit.attach(master.execute, master.stats)
    return Bench(clock, transport, master, observer, {d.address: d for d in fc}), reports, audit


def _accesses(b: Bench, address: int) -> list[tuple[float, str, int, int]]:
    """Every request to ``address`` touching 8-03/8-04: (time, "read"|"write", pnu, pwe)."""
    out = []
    for at, telegram in b.requests(address):
        if telegram.pnu in (TIME, FUNCTION):
            kind = "write" if telegram.ak in WRITES else "read"
            out.append((at, kind, telegram.pnu, telegram.pwe))
    return out


def _first_reply_at(b: Bench, name: str) -> float:
    return next(at for drive, _, at, _ in b.observer.replies if drive == name)


# -- the verdict rules -------------------------------------------------------------------


@pytest.mark.parametrize(
    ("setting", "round_s", "verdict"),
    [
        (WatchdogSetting(timeout_s=None, action="off", stops=False), 0.1, Verdict.OFF),
        (WatchdogSetting(timeout_s=5.0, action="freeze output", stops=False), 0.1, Verdict.OFF),
        (WatchdogSetting(timeout_s=5.0, action="select set-up 2", stops=None), 0.1,
         Verdict.UNKNOWN),
        (WatchdogSetting(timeout_s=0.05, action="stop", stops=True), 0.1, Verdict.TOO_SHORT),
        (WatchdogSetting(timeout_s=0.0, action="trip", stops=True), 0.001, Verdict.TOO_SHORT),
        (WatchdogSetting(timeout_s=0.1, action="stop", stops=True), 0.1, Verdict.OK),
        (WatchdogSetting(timeout_s=2.0, action="trip", stops=True), 0.1, Verdict.OK),
    ],
    ids=["off", "runs-on", "set-up-switch", "shorter-than-round", "zero", "equal", "longer"],
)  # fmt: skip
def test_verdict_rules(setting: WatchdogSetting, round_s: float, verdict: Verdict) -> None:
    assert judge(setting, round_s) is verdict


# -- reads at adoption and on return -------------------------------------------------------


async def test_watchdog_is_read_once_the_drive_is_adopted_and_judged_off() -> None:
    a = DrivePlan(name="a", address=1, control=True)
    b, reports, audit = _bench(a, fc=[_drive(1, 600, 0)])
    with structlog.testing.capture_logs() as logs:
        async with b.master:
            await b.clock.run_until(T0 + 3.0)
            await audit.aclose()
    adopted = _first_reply_at(b, "a")
    accesses = _accesses(b, 1)
    assert [(kind, pnu) for _, kind, pnu, _ in accesses] == [("read", TIME), ("read", FUNCTION)]
    assert all(at > adopted for at, *_ in accesses)
    assert reports == [("a", WatchdogReport(None, "off", Verdict.OFF))]
    warning = next(e for e in logs if e["event"] == "drive.watchdog_off")
    assert warning["log_level"] == "warning"
    assert warning["drive"] == "a"
    assert "8-04" in warning["fix"]
    assert "[2] Stop" in warning["fix"]
    # the reads are housekeeping: no audit line and no command event, unlike a caller's
    assert [e for e in logs if e["event"] == "command.completed"] == []
    assert b.observer.results == []


async def test_a_stop_with_a_timeout_longer_than_the_round_is_ok() -> None:
    a = DrivePlan(name="a", address=1, control=True)
    b, reports, audit = _bench(a, fc=[_drive(1, 20, 2)])
    with structlog.testing.capture_logs() as logs:
        async with b.master:
            await b.clock.run_until(T0 + 3.0)
            await audit.aclose()
    assert reports == [("a", WatchdogReport(2.0, "stop", Verdict.OK))]
    assert not [e for e in logs if e["log_level"] == "warning"]


async def test_a_timeout_shorter_than_the_worst_round_is_too_short() -> None:
    plans = [DrivePlan(name=n, address=i, control=True) for i, n in enumerate("abc", 1)]
    # 3 drives at 9600 baud: a round takes longer than 0.1 s
    b, reports, audit = _bench(
        *plans, fc=[_drive(1, 1, 2), _drive(2, 600, 2), _drive(3, 600, 2)], baudrate=9600
    )
    round_s = poll_round_s(b.plan)[0]
    assert round_s > 0.1
    with structlog.testing.capture_logs() as logs:
        async with b.master:
            await b.clock.run_until(T0 + 5.0)
            await audit.aclose()
    assert dict(reports) == {
        "a": WatchdogReport(0.1, "stop", Verdict.TOO_SHORT),
        "b": WatchdogReport(60.0, "stop", Verdict.OK),
        "c": WatchdogReport(60.0, "stop", Verdict.OK),
    }
    warning = next(e for e in logs if e["event"] == "drive.watchdog_too_short")
    assert warning["log_level"] == "warning"
    assert warning["timeout_s"] == 0.1
    assert warning["poll_round_s"] == pytest.approx(round_s, abs=1e-4)
    assert "8-03" in warning["fix"]


async def test_a_drive_whose_parameters_cannot_be_read_is_unknown() -> None:
    a = DrivePlan(name="a", address=1, control=True)
    b, reports, audit = _bench(a, fc=[FcDrive(1)])  # no 8-03/8-04: refused (AK 7)
    async with b.master:
        await b.clock.run_until(T0 + 3.0)
        await audit.aclose()
    assert reports == [("a", WatchdogReport(None, "unknown", Verdict.UNKNOWN))]


async def test_a_monitor_only_drive_is_not_audited() -> None:
    m = DrivePlan(name="m", address=3)
    b, reports, audit = _bench(m, fc=[_drive(3, 600, 0)])
    async with b.master:
        await b.clock.run_until(T0 + 3.0)
        await audit.aclose()
    assert _accesses(b, 3) == []
    assert reports == []


async def test_watchdog_is_read_again_when_the_drive_returns_online() -> None:
    a = DrivePlan(name="a", address=1, control=True)
    fc = _drive(1, 20, 2)
    b, reports, audit = _bench(a, fc=[fc], probe_interval_s=0.5)
    async with b.master:
        await b.clock.run_until(T0 + 1.0)
        fc.silent = True
        await b.clock.run_until(T0 + 2.0)
        assert [name for name, online, _ in b.observer.availability] == ["a", "a"]
        fc.parameters[FUNCTION] = 0  # replaced meanwhile by a drive at factory settings
        fc.silent = False
        back = b.clock.now()
        await b.clock.run_until(T0 + 4.0)
        await audit.aclose()
    reads = [(at, pnu) for at, kind, pnu, _ in _accesses(b, 1) if kind == "read"]
    assert [pnu for at, pnu in reads if at < back] == [TIME, FUNCTION]
    assert [pnu for at, pnu in reads if at > back] == [TIME, FUNCTION]
    assert [r for _, r in reports] == [
        WatchdogReport(2.0, "stop", Verdict.OK),
        WatchdogReport(None, "off", Verdict.OFF),
    ]


async def test_watchdog_is_read_again_after_the_line_was_down() -> None:
    a = DrivePlan(name="a", address=1, control=True)
    b, reports, audit = _bench(a, fc=[_drive(1, 20, 2)])
    async with b.master:
        await b.clock.run_until(T0 + 1.0)
        b.transport.lost = True
        await b.clock.run_until(T0 + 1.1)
        b.transport.lost = False
        await b.clock.run_until(T0 + 4.0)
        await audit.aclose()
    reads = [pnu for _, kind, pnu, _ in _accesses(b, 1) if kind == "read"]
    assert reads == [TIME, FUNCTION, TIME, FUNCTION]
    assert len(reports) == 2


# -- a configured watchdog -----------------------------------------------------------------


async def test_configured_watchdog_is_written_time_first_and_read_back() -> None:
    a = DrivePlan(name="a", address=1, control=True, watchdog=WatchdogPlan(3.0, "stop"))
    fc = _drive(1, 600, 0)
    b, reports, audit = _bench(a, fc=[fc])
    with structlog.testing.capture_logs() as logs:
        async with b.master:
            await b.clock.run_until(T0 + 3.0)
            await audit.aclose()
    assert [(kind, pnu, pwe) for _, kind, pnu, pwe in _accesses(b, 1)] == [
        ("read", TIME, 0),
        ("read", FUNCTION, 0),
        ("write", TIME, 30),  # 3.0 s in 0.1 s
        ("write", FUNCTION, 2),  # [2] Stop
        ("read", TIME, 0),
        ("read", FUNCTION, 0),
    ]
    assert (fc.parameters[TIME], fc.parameters[FUNCTION]) == (30, 2)
    assert reports == [("a", WatchdogReport(3.0, "stop", Verdict.OK))]
    assert any(e["event"] == "drive.watchdog_written" for e in logs)
    # the writes change the drive: each is audited as a command
    audited = [
        (e["actor"], e["command"], e["parameter"], e["value"], e["outcome"])
        for e in logs
        if e["event"] == "command.completed"
    ]
    assert audited == [
        ("watchdog-audit", "write", "8-03", 3.0, "done"),
        ("watchdog-audit", "write", "8-04", 2, "done"),
    ]
    assert not any(e["event"] == "drive.watchdog_off" for e in logs)


async def test_configured_watchdog_already_in_the_drive_is_not_written_again() -> None:
    a = DrivePlan(name="a", address=1, control=True, watchdog=WatchdogPlan(3.0, "trip"))
    b, reports, audit = _bench(a, fc=[_drive(1, 30, 5)])
    async with b.master:
        await b.clock.run_until(T0 + 3.0)
        await audit.aclose()
    assert [kind for _, kind, _, _ in _accesses(b, 1)] == ["read", "read"]
    assert reports == [("a", WatchdogReport(3.0, "stop and trip", Verdict.OK))]


def _refusing_function_writes(fc: FcDrive) -> Responder:
    """``fc``'s line, but a write of 8-04 is refused (error 17: not in this mode)."""
    line = FcLine(fc)

    def respond(request: bytes) -> bytes | Timed | None:
        telegram = decode_telegram(request, from_drive=False)
        if telegram.pnu == FUNCTION and telegram.ak in WRITES:
            pke = make_pke(ResponseAk.ERROR, FUNCTION)
            return reply_frame(1, fc.status_word, pke=pke, pwe=17)
        return line(request)

    return respond


async def test_a_refused_write_leaves_the_verdict_to_what_the_drive_reads_back() -> None:
    a = DrivePlan(name="a", address=1, control=True, watchdog=WatchdogPlan(3.0, "stop"))
    fc = _drive(1, 600, 0)
    b, reports, audit = _bench(a, fc=[fc], responder=_refusing_function_writes(fc))
    with structlog.testing.capture_logs() as logs:
        async with b.master:
            await b.clock.run_until(T0 + 3.0)
            await audit.aclose()
    failed = next(e for e in logs if e["event"] == "drive.watchdog_write_failed")
    assert failed["param"] == "8-04"
    assert failed["outcome"] == "refused"
    # 8-03 took 3.0 s, 8-04 stayed Off: the read-back says off, whatever was asked
    assert (fc.parameters[TIME], fc.parameters[FUNCTION]) == (30, 0)
    assert reports == [("a", WatchdogReport(None, "off", Verdict.OFF))]


async def test_the_audit_of_a_whole_line_never_starves_the_polls() -> None:
    plans = [DrivePlan(name=f"d{i}", address=i, control=True) for i in range(1, 9)]
    b, reports, audit = _bench(*plans, fc=[_drive(i, 20, 2) for i in range(1, 9)])
    async with b.master:
        await b.clock.run_until(T0 + 12.0)
        await audit.aclose()
    assert len(reports) == 8  # every drive audited: 16 reads
    round_s = poll_round_s(b.plan)[0]
    one_exchange_s = round_s / 8
    for address in range(1, 9):
        times = [at for at, _ in b.requests(address)]
        gaps = [later - earlier for earlier, later in itertools.pairwise(times)]
        # Between two telegrams to a drive: one round of polls, and at most one audit read
        # of another drive in it (the audit rests nine times as long as each exchange).
        assert max(gaps) <= round_s + one_exchange_s + 1e-6, address
    audit_reads = sorted(at for a in range(1, 9) for at, *_ in _accesses(b, a))
    spacing = [later - earlier for earlier, later in itertools.pairwise(audit_reads)]
    assert min(spacing) >= 9 * one_exchange_s * 0.9


async def test_nothing_goes_out_for_the_audit_once_shutdown_began() -> None:
    a = DrivePlan(name="a", address=1, control=True)
    b, reports, audit = _bench(a, fc=[_drive(1, 20, 2)])
    async with b.master:
        audit.stop()  # as the service does when the shutdown begins
        await b.clock.run_until(T0 + 3.0)
        await audit.aclose()
    assert b.observer.availability == [("a", True, b.observer.availability[0][2])]
    assert _accesses(b, 1) == []
    assert reports == []


def test_replies_reach_the_inner_observer_without_a_call_of_the_audits_own() -> None:
    recorder = Recorder()
    plan = LinePlan(name="line1", port="x")
    audit = WatchdogAudit(plan, clock=VirtualClock(T0), report=lambda *_: None)
    observer = audit.observing(recorder)
    # the hot path (every reply) is the inner observer's own bound method, not a wrapper
    assert observer.drive_replied == recorder.drive_replied
    assert observer.command_completed == recorder.command_completed


async def test_a_refused_write_is_tried_again_once_per_stop_not_in_a_loop() -> None:
    a = DrivePlan(name="a", address=1, control=True, watchdog=WatchdogPlan(3.0, "stop"))
    fc = _drive(1, 600, 0)  # stopped all along
    b, reports, audit = _bench(a, fc=[fc], responder=_refusing_function_writes(fc))
    with structlog.testing.capture_logs() as logs:
        async with b.master:
            await b.clock.run_until(T0 + 60.0)
            await audit.aclose()
    function_writes = [
        at for at, kind, pnu, _ in _accesses(b, 1) if (kind, pnu) == ("write", FUNCTION)
    ]
    # Refused at adoption, tried once more at the first stopped status (it was stopped), then
    # never again: the drive did not run and stop anew in the minute that followed.
    assert len(function_writes) == 2
    assert function_writes[1] - function_writes[0] < 2.0
    assert [e["event"] for e in logs if e["event"].startswith("drive.watchdog_write")] == [
        "drive.watchdog_write_failed",
        "drive.watchdog_write_retried",
        "drive.watchdog_write_failed",
    ]
    assert reports == [("a", WatchdogReport(None, "off", Verdict.OFF))]  # one verdict, no repeat


async def test_a_drive_that_loses_power_during_its_audit_keeps_its_verdict_until_it_returns() -> (
    None
):
    a = DrivePlan(name="a", address=1, control=True)
    fc = _drive(1, 20, 2)
    b, reports, audit = _bench(a, fc=[fc], probe_interval_s=0.5)
    with structlog.testing.capture_logs() as logs:
        async with b.master:
            await b.clock.run_until(T0 + 3.0)
            assert [r for _, r in reports] == [WatchdogReport(2.0, "stop", Verdict.OK)]
            fc.silent = True  # powered down …
            await b.clock.run_until(T0 + 4.0)
            fc.silent = False  # … back: audited again, and again gone after its first read
            back = b.clock.now()
            while not [1 for at, kind, _, _ in _accesses(b, 1) if at > back and kind == "read"]:
                await b.clock.run_until(b.clock.now() + 0.01)
            fc.silent = True
            await b.clock.run_until(T0 + 10.0)
            assert [r for _, r in reports] == [WatchdogReport(2.0, "stop", Verdict.OK)]
            fc.silent = False  # back for good: the audit ends with a verdict again
            await b.clock.run_until(T0 + 14.0)
            await audit.aclose()
    # what a powered-down drive did not answer is no verdict: no "unknown" in between
    assert [r.verdict for _, r in reports] == [Verdict.OK, Verdict.OK]
    assert not any(e["event"] == "drive.watchdog_unknown" for e in logs)


async def test_the_same_warning_is_given_once_not_at_every_return_of_the_drive() -> None:
    a = DrivePlan(name="a", address=1, control=True)
    fc = _drive(1, 600, 0)  # factory: Off
    b, reports, audit = _bench(a, fc=[fc], probe_interval_s=0.5)
    with structlog.testing.capture_logs() as logs:
        async with b.master:
            for start in (3.0, 6.0, 9.0):
                await b.clock.run_until(T0 + start)
                fc.silent = True
                await b.clock.run_until(T0 + start + 1.0)
                fc.silent = False
            await b.clock.run_until(T0 + 14.0)
            await audit.aclose()
    assert [r.verdict for _, r in reports] == [Verdict.OFF] * 4  # audited at every return
    events = [e["event"] for e in logs if e["event"].startswith("drive.watchdog_")]
    assert events == ["drive.watchdog_off"] + ["drive.watchdog_unchanged"] * 3


# -- what a restart costs ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("timeout_s", "round_s", "gap_s", "verdict"),
    [
        (2.0, 0.1, 1.0, Verdict.OK),
        (2.0, 0.1, 2.5, Verdict.TOO_SHORT),
        (2.0, 2.5, 1.0, Verdict.TOO_SHORT),
        (2.0, 1.0, 1.5, Verdict.TOO_SHORT),  # the valid word comes a round after the gap
    ],
    ids=["both-fit", "restart-longer", "round-longer", "together-longer"],
)
def test_the_verdict_is_ok_only_when_the_round_and_the_restart_gap_both_fit(
    timeout_s: float, round_s: float, gap_s: float, verdict: Verdict
) -> None:
    setting = WatchdogSetting(timeout_s=timeout_s, action="stop", stops=True)
    assert judge(setting, round_s, gap_s) is verdict


async def test_a_timeout_shorter_than_the_restart_gap_is_too_short_and_the_gap_shown() -> None:
    a = DrivePlan(name="a", address=1, control=True)
    b, reports, audit = _bench(a, fc=[_drive(1, 20, 2)])  # 2.0 s, stop: ok for the round
    b.transport.fail_open = True  # the adapter is not there yet when the daemon starts
    with structlog.testing.capture_logs() as logs:
        async with b.master:
            await b.clock.run_until(T0 + 2.5)
            b.transport.fail_open = False
            await b.clock.run_until(T0 + 12.0)
            await audit.aclose()
    first = b.requests(1)[0][0]
    assert first > T0 + 2.5
    ((name, report),) = reports
    assert (name, report.timeout_s, report.verdict) == ("a", 2.0, Verdict.TOO_SHORT)
    assert report.restart_gap_s == pytest.approx(first - T0)  # the first telegram to it
    assert report.to_json()["restart_gap_s"] == report.restart_gap_s
    warning = next(e for e in logs if e["event"] == "drive.watchdog_too_short")
    assert warning["consequence"] == "a gateway restart trips the drive"
    assert warning["restart_gap_s"] == pytest.approx(report.restart_gap_s, abs=1e-3)


async def test_a_drive_powered_up_late_is_judged_by_the_first_telegram_it_was_sent() -> None:
    a = DrivePlan(name="a", address=1, control=True)
    b, reports, audit = _bench(a, fc=[_drive(1, 10, 2, silent=True)])  # 1.0 s, stop
    async with b.master:
        await b.clock.run_until(T0 + 8.0)  # unpowered: its watchdog is not running either
        b.drives[1].silent = False
        await b.clock.run_until(T0 + 20.0)
        await audit.aclose()
    ((name, report),) = reports
    assert _first_reply_at(b, "a") > T0 + 8.0
    assert report.restart_gap_s == pytest.approx(b.requests(1)[0][0] - T0)
    assert report.restart_gap_s is not None
    assert report.restart_gap_s < 0.1
    assert (name, report.verdict) == ("a", Verdict.OK)


async def test_a_modbus_drive_whose_profile_names_no_watchdog_registers_is_unknown() -> None:
    # Nothing is read, so nothing says whether the motor stops if the gateway dies: unknown,
    # not off (which would warn that it keeps running).
    profile = dataclasses.replace(BUILT_IN["abb-drives"], watchdog=WatchdogProfile())
    a = DrivePlan(name="a", address=1, control=True, profile=profile)
    plan = LinePlan(name="line1", port="x", protocol="modbus-rtu", drives=(a,))
    reports: list[WatchdogReport] = []
    audit = WatchdogAudit(plan, clock=VirtualClock(T0), report=lambda _b, _n, r: reports.append(r))
    commands: list[Command] = []

    async def execute(name: str, command: Command) -> CommandResult:
        commands.append(command)
        return CommandResult(outcome=Outcome.REFUSED, reason="not expected")

    audit.attach(execute)
    with structlog.testing.capture_logs() as logs:
        audit.drive_online(a, T0)
        await asyncio.sleep(0)  # the audit's task runs: it has nothing to wait for
        await audit.aclose()
    assert commands == []
    assert reports == [WatchdogReport(None, "unknown", Verdict.UNKNOWN, 0.0)]
    assert [e["event"] for e in logs] == ["drive.watchdog_unknown"]
