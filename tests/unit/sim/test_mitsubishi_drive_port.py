"""Mitsubishi's two ports: the line key ``drive_port`` picks the check the audit reads and writes.

From the manuals (protocols/mitsubishi.md §1.1): the PU connector's communication check time
interval is Pr.122 and its trip E.PUE (fault code HB1); the RS-485 terminals' is Pr.336 and
their trip E.SER (HC6). Both take 0.1-999.8 s, 9999 = no check, travel in 0.1 s. The real
BusMaster, the real audit and simulated inverters in virtual time; every drive below has the
two checks set differently, so a test reading the wrong one fails.
"""

from __future__ import annotations

import dataclasses

import pytest
import structlog.testing

from fcmaster.bus.codecs import codec_for, with_protocol_delay
from fcmaster.bus.commands import Action, Command, CommandResult
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan, WatchdogPlan
from fcmaster.bus.watchdog import Verdict, WatchdogAudit, WatchdogReport
from fcmaster.config import parse
from fcmaster.errors import ConfigError
from fcmaster.protocol.codec import Reply
from fcmaster.protocol.mitsubishi.spec import SPEC
from fcmaster.sim import DriveSettings, LineSettings, MitsubishiSimDrive, SimTransport, build_line
from tests.fakes import VirtualClock
from tests.orders import orders

E_PUE, E_SER = 0xB1, 0xC6


def _line(port: str | None, *drives: DrivePlan) -> LinePlan:
    options = () if port is None else (("drive_port", port),)
    return LinePlan(
        name="line1", port="sim://line1", protocol="mitsubishi", stopbits=2,
        drives=drives, protocol_options=options,
    )  # fmt: skip


@dataclasses.dataclass
class _Bench:
    master: BusMaster
    audit: WatchdogAudit
    reports: list[WatchdogReport]
    drives: list[MitsubishiSimDrive]
    writes: list[tuple[float, str | None]]  # when the audit put each write to the master
    running: list[tuple[float, bool]]  # when each reply said the motor was running or not


def _bench(
    plan: LinePlan, clock: VirtualClock, running_hz: float = 0.0, **parameters: float
) -> _Bench:
    settings = DriveSettings(
        running_hz=running_hz,
        parameters={k.replace("_", "."): v for k, v in parameters.items()},
    )
    line = build_line(
        LineSettings(protocol="mitsubishi", stopbits=2, protocol_options=plan.protocol_options),
        [(d.address, settings) for d in plan.drives],
        clock=clock,
    )
    plan = with_protocol_delay(plan)
    reports: list[WatchdogReport] = []
    audit = WatchdogAudit(plan, clock=clock, report=lambda _b, _n, r: reports.append(r))
    observer = _Observer()
    master = BusMaster(
        plan,
        codec=codec_for(plan),
        transport=SimTransport(line, clock),
        clock=clock,
        observer=audit.observing(observer),
    )
    writes: list[tuple[float, str | None]] = []

    async def execute(name: str, command: Command) -> CommandResult:
        if command.action is Action.WRITE:
            writes.append((clock.now(), command.parameter))
        return await master.execute(name, command)

    audit.attach(execute)
    drives = [d for d in line.drives if isinstance(d, MitsubishiSimDrive)]
    return _Bench(master, audit, reports, drives, writes, observer.running)


class _Observer:
    """Keeps only when each reply said the motor was running or not."""

    def __init__(self) -> None:
        self.running: list[tuple[float, bool]] = []

    def drive_replied(
        self, bus: str, drive: DrivePlan, reply: Reply, at: float, *_: object
    ) -> None:
        if reply.status is not None:
            self.running.append((at, reply.status.running))

    def drive_availability(self, *args: object) -> None:
        pass

    def line_availability(self, *args: object) -> None:
        pass

    def command_completed(self, *args: object) -> None:
        pass


@pytest.mark.parametrize(
    ("port", "parameter"), [(None, "Pr.122"), ("pu", "Pr.122"), ("terminals", "Pr.336")]
)
def test_the_line_key_selects_the_check_parameter(port: str | None, parameter: str) -> None:
    facts = SPEC.watchdog_of(_line(port))
    assert facts.parameters == (parameter,)
    assert facts.encode(2.5, "trip") == ((parameter, 2.5),)
    assert parameter in facts.advice(2.0)
    assert facts.decode([9999.0]).timeout_s is None  # 9999: no check, on either port


@pytest.mark.parametrize(
    ("port", "verdict", "timeout_s"), [("pu", Verdict.OFF, None), ("terminals", Verdict.OK, 3.0)]
)
async def test_the_audit_reads_the_check_of_the_port_the_line_is_wired_to(
    port: str, verdict: Verdict, timeout_s: float | None
) -> None:
    clock = VirtualClock()
    plan = _line(port, DrivePlan(name="d1", address=1, control=True))
    # The PU connector's check is off, the terminals' is 3 s: only the wired one counts.
    b = _bench(plan, clock, Pr_122=9999, Pr_336=3.0)
    async with b.master:
        await clock.run_for(10.0)
    await b.audit.aclose()
    assert [(r.verdict, r.timeout_s) for r in b.reports] == [(verdict, timeout_s)]


async def test_a_configured_watchdog_is_written_to_pr336_on_the_terminals() -> None:
    clock = VirtualClock()
    drive = DrivePlan(name="d1", address=1, control=True, watchdog=WatchdogPlan(2.0, "trip"))
    b = _bench(_line("terminals", drive), clock, Pr_122=9999)
    async with b.master:
        await clock.run_for(15.0)
        assert [(r.verdict, r.timeout_s) for r in b.reports] == [(Verdict.OK, 2.0)]
        assert b.drives[0].parameters[336] == 20  # 2.0 s in 0.1 s
        assert b.drives[0].parameters.value(122) == 9999  # the PU connector's is left alone
    await b.audit.aclose()
    assert [p for _, p in b.writes] == ["Pr.336"]


@pytest.mark.parametrize(("port", "trip"), [("pu", E_PUE), ("terminals", E_SER)])
async def test_the_simulated_drive_trips_on_the_check_of_its_port(port: str, trip: int) -> None:
    clock = VirtualClock()
    plan = _line(port, DrivePlan(name="d1", address=1, control=True))
    # The other port's check is short but never armed: it hears nothing.
    wired, other = ("Pr.122", "Pr.336") if port == "pu" else ("Pr.336", "Pr.122")
    b = _bench(plan, clock, **{wired.replace(".", "_"): 1.0, other.replace(".", "_"): 0.2})
    drives = b.drives
    async with b.master:
        assert (await clock.complete(orders(b.master, "d1").start(frequency_hz=20.0))).ok
        await clock.run_for(3.0)
        drives[0].advance(clock.now())
        assert drives[0].control.fault is None  # fed by the polls; the other never armed
    await b.audit.aclose()
    await clock.run_for(0.9)
    drives[0].advance(clock.now())
    assert drives[0].control.fault is None  # not yet the wired check's 1 s
    await clock.run_for(0.3)
    drives[0].advance(clock.now())
    assert drives[0].control.fault == trip
    assert not drives[0].motor.output_on


def _config(extra: str, protocol: str = "mitsubishi") -> str:
    return f"""
buses:
  - name: line1
    port: /dev/ttyUSB0
    protocol: {protocol}
{extra}
    drives:
      - {{name: d1, address: 1}}
"""


def test_config_takes_drive_port_into_the_line_plan() -> None:
    (line,) = parse(_config("    drive_port: terminals")).lines
    assert dict(line.protocol_options)["drive_port"] == "terminals"
    assert SPEC.watchdog_of(line).parameters == ("Pr.336",)
    (default,) = parse(_config("")).lines
    assert SPEC.watchdog_of(default).parameters == ("Pr.122",)


@pytest.mark.parametrize(
    ("extra", "protocol", "words"),
    [
        ("    drive_port: rs485", "mitsubishi", "terminals"),
        ("    drive_port: terminals", "danfoss-fc", "only mitsubishi lines"),
    ],
)
def test_config_refuses_a_bad_drive_port_naming_the_key(
    extra: str, protocol: str, words: str
) -> None:
    with pytest.raises(ConfigError) as caught:
        parse(_config(extra, protocol))
    problems = dict(caught.value.problems)
    assert any(path.endswith("drive_port") for path in problems), problems
    assert any(words in reason for reason in problems.values()), problems


# -- a write refused while running -------------------------------------------------------


async def test_a_write_refused_while_running_is_written_once_the_drive_is_seen_stopped() -> None:
    clock = VirtualClock()
    drive = DrivePlan(name="d1", address=1, control=True, watchdog=WatchdogPlan(2.0, "trip"))
    plan = _line("pu", drive)
    # Running at adoption (kept running): Pr.77 = 0, so the drive refuses Pr.122 (mode error A).
    settings = {"Pr_122": 9999.0, "Pr_8": 1.0}  # deceleration 1 s
    b = _bench(plan, clock, running_hz=30.0, **settings)
    master, reports, drives, writes = b.master, b.reports, b.drives, b.writes
    with structlog.testing.capture_logs() as logs:
        async with master:
            await clock.run_for(10.0)
            assert drives[0].motor.output_on  # still running: nothing more was tried
            assert [r.verdict for r in reports] == [Verdict.OFF]
            assert drives[0].parameters.value(122) == 9999
            stop_at = clock.now()
            assert (await clock.complete(orders(master, "d1").stop())).ok
            await clock.run_for(10.0)
        await b.audit.aclose()
    failed = [e for e in logs if e["event"] == "drive.watchdog_write_failed"]
    assert [(e["param"], e["outcome"]) for e in failed] == [("Pr.122", "refused")]
    retried = [e for e in logs if e["event"] == "drive.watchdog_write_retried"]
    assert len(retried) == 1
    assert [(r.verdict, r.timeout_s) for r in reports] == [(Verdict.OFF, None), (Verdict.OK, 2.0)]
    assert drives[0].parameters[122] == 20  # 2.0 s, in 0.1 s
    # Two writes: the refused one at adoption, then one after a reply showed the motor off
    # (the stop ramps 30 Hz down in about 0.6 s of Pr.8's 1 s per 50 Hz).
    assert [p for _, p in writes] == ["Pr.122", "Pr.122"]
    stopped_at = next(at for at, running in b.running if at > stop_at and not running)
    assert writes[0][0] < stop_at < stop_at + 0.5 < stopped_at <= writes[1][0]
    assert writes[1][0] - stopped_at < 1.0  # promptly: within a few polls of the stop
    assert drives[0].control.fault is None
