"""The service's shutdown with ``on_shutdown: stop``, in virtual time: what it says per drive.

A Service runs one scripted FC line of two bus-controlled drives, both running, on a
:class:`~tests.fakes.VirtualClock`. At the stop, each drive's stop ends with an outcome,
and the log says the truth about it: nothing beyond the audit line when the drive stopped,
an error naming the drive when its stop never reached it (the motor may still turn), a
warning when the drive took it but did not show it stopping in time.
"""

from __future__ import annotations

import asyncio
from collections.abc import MutableMapping
from typing import Any

import structlog.testing

from fcmaster.bus.commands import Action, Command, Outcome
from fcmaster.config import parse
from fcmaster.protocol.danfoss_fc import ControlWord
from fcmaster.service import Service
from tests.fakes import ScriptedTransport, VirtualClock
from tests.unit.bus.bench import DELAY_S, STOP_WORD, T0
from tests.unit.bus.fcdrive import FcDrive, FcLine

CONFIG = """
buses:
  - name: line1
    port: /dev/ttyTEST
    baudrate: 19200
    drives:
      - {name: a, address: 1, control: bus}
      - {name: b, address: 2, control: bus}
on_shutdown: stop
"""


class Unstoppable(FcDrive):
    """A drive that acknowledges every telegram and keeps turning (a stuck contactor)."""

    def _control(self, ctw: int, ref: int) -> None:
        self.running, self.output_pct = True, 50.0


async def shut_down(
    *drives: FcDrive,
    before_stop: Any = None,
    config: str = CONFIG,
    clock: VirtualClock | None = None,
) -> list[MutableMapping[str, Any]]:
    """Run the service until both drives are online, stop it; the events it logged then."""
    return (await shut_down_service(*drives, before_stop=before_stop, config=config, clock=clock))[
        1
    ]


async def shut_down_service(
    *drives: FcDrive,
    before_stop: Any = None,
    config: str = CONFIG,
    clock: VirtualClock | None = None,
) -> tuple[Service, list[MutableMapping[str, Any]]]:
    """:func:`shut_down`, with the service that ran."""
    clock = clock or VirtualClock(T0)
    transports: list[ScriptedTransport] = []

    def scripted(_: object) -> ScriptedTransport:
        transports.append(ScriptedTransport(clock, FcLine(*drives), delay_s=DELAY_S))
        return transports[-1]

    service = Service(parse(config), clock=clock, transport_factory=scripted)
    task = asyncio.ensure_future(service.run(install_signals=False))
    await clock.run_until(T0 + 1.0)
    assert all(state.online for state in service.fleet.snapshot())
    if before_stop is not None:
        before_stop(transports[0])
    with structlog.testing.capture_logs() as logs:
        service.stop()
        await clock.complete(task, within=60.0)
    return service, logs


def service_events(logs: list[MutableMapping[str, Any]]) -> list[tuple[str, str, str | None]]:
    return [
        (e["event"], e["log_level"], e.get("drive") or ",".join(e.get("drives", [])) or None)
        for e in logs
        if e["event"].startswith("service.shutdown")
    ]


def stops(logs: list[MutableMapping[str, Any]]) -> dict[str, str]:
    return {
        e["drive"]: e["outcome"]
        for e in logs
        if e["event"] == "command.completed" and e["actor"] == "shutdown"
    }


async def test_stops_that_reach_their_drives_are_done_and_nothing_else_is_said() -> None:
    drives = (FcDrive(1, running=True, output_pct=50.0), FcDrive(2, running=True, output_pct=50.0))
    logs = await shut_down(*drives)
    assert stops(logs) == {"a": "done", "b": "done"}
    assert service_events(logs) == []
    assert not [e for e in logs if e["log_level"] in ("error", "critical")]
    assert [d.received[-1].pcd1 for d in drives] == [STOP_WORD, STOP_WORD]
    assert not any(d.running for d in drives)


async def test_a_stop_the_drive_never_answers_is_an_error_naming_the_drive() -> None:
    a, b = FcDrive(1, running=True, output_pct=50.0), FcDrive(2, running=True, output_pct=50.0)

    def power_off_b(_: ScriptedTransport) -> None:
        b.silent = True

    logs = await shut_down(a, b, before_stop=power_off_b)
    assert stops(logs) == {"a": "done", "b": "timeout"}
    assert service_events(logs) == [("service.shutdown_stop_failed", "error", "b")]
    (failed,) = [e for e in logs if e["event"] == "service.shutdown_stop_failed"]
    assert failed["outcome"] == "timeout"
    assert failed["reason"].startswith("no valid reply from b")
    assert not a.running


async def test_stops_cancelled_because_the_port_is_gone_are_errors_naming_each_drive() -> None:
    drives = (FcDrive(1, running=True, output_pct=50.0), FcDrive(2, running=True, output_pct=50.0))

    def unplug(transport: ScriptedTransport) -> None:
        transport.lost = True
        transport.fail_open = True

    logs = await shut_down(*drives, before_stop=unplug)
    assert stops(logs) == {"a": "cancelled", "b": "cancelled"}
    assert service_events(logs) == [
        ("service.shutdown_stop_failed", "error", "a"),
        ("service.shutdown_stop_failed", "error", "b"),
    ]
    assert all(d.running for d in drives)  # what the errors warn of


async def test_the_drives_whose_stop_failed_are_named_for_the_exit_status() -> None:
    a, b = FcDrive(1, running=True, output_pct=50.0), FcDrive(2, running=True, output_pct=50.0)

    def power_off_b(_: ScriptedTransport) -> None:
        b.silent = True

    service, _ = await shut_down_service(a, b, before_stop=power_off_b)
    assert service.stops_failed == ["line1/b"]
    service, _ = await shut_down_service(
        FcDrive(1, running=True, output_pct=50.0), FcDrive(2, running=True, output_pct=50.0)
    )
    assert service.stops_failed == []


async def test_a_drive_still_turning_at_the_bound_is_a_warning_naming_it() -> None:
    a, b = FcDrive(1, running=True, output_pct=50.0), Unstoppable(2, running=True, output_pct=50.0)
    logs = await shut_down(a, b)
    assert stops(logs)["a"] == "done"
    assert service_events(logs) == [("service.shutdown_stop_timed_out", "warning", "line1/b")]
    assert b.received[-1].pcd1 == STOP_WORD  # it was told


async def test_a_drive_in_local_operation_leaves_its_stop_unconfirmed_a_warning() -> None:
    a = FcDrive(1, running=True, output_pct=50.0)
    b = FcDrive(2, running=True, output_pct=50.0, local=True)
    logs = await shut_down(a, b)
    assert stops(logs) == {"a": "done", "b": "unconfirmed"}
    assert service_events(logs) == [("service.shutdown_stop_unconfirmed", "warning", "b")]


class Ramping(FcDrive):
    """A drive that ramps down over its 3-42 after a stop word (from 100 %), on ``clock``."""

    def __init__(self, address: int, clock: VirtualClock, ramp_s: float) -> None:
        super().__init__(address, running=True, output_pct=50.0)
        self.parameters[342] = round(ramp_s * 100)
        self.clock, self.ramp_s = clock, ramp_s
        self.stop_at: float | None = None

    def _control(self, ctw: int, ref: int) -> None:
        if not ctw & ControlWord.DATA_VALID or ctw & ControlWord.START:
            super()._control(ctw, ref)
            return
        now = self.clock.now()
        if self.stop_at is None:
            self.stop_at = now + self.ramp_s * self.output_pct / 100.0
        self.running = now < self.stop_at


async def test_the_shutdown_waits_for_a_stop_as_long_as_its_drive_ramps() -> None:
    clock = VirtualClock(T0)
    a, b = FcDrive(1, running=True, output_pct=50.0), Ramping(2, clock, ramp_s=30.0)
    logs = await shut_down(a, b, clock=clock)
    assert stops(logs) == {"a": "done", "b": "done"}  # b stood after 15 s, beyond the 5 s floor
    assert service_events(logs) == []
    assert b.stop_at is not None
    assert clock.now() >= b.stop_at


async def test_the_shutdown_waits_no_longer_than_shutdown_timeout_s() -> None:
    clock = VirtualClock(T0)
    a, b = FcDrive(1, running=True, output_pct=50.0), Ramping(2, clock, ramp_s=60.0)
    config = CONFIG + "shutdown_timeout_s: 12\n"
    logs = await shut_down(a, b, config=config, clock=clock)
    assert stops(logs)["a"] == "done"
    assert service_events(logs) == [("service.shutdown_stop_timed_out", "warning", "line1/b")]
    assert b.stop_at is not None
    assert clock.now() < b.stop_at  # 30 s to stand; the bound was 12 s
    assert 12.0 <= clock.now() - (T0 + 1.0) < 13.0  # stopped at T0 + 1 s (virtual time)


async def test_a_command_arriving_during_the_shutdown_is_audited_cancelled_with_its_values() -> (
    None
):
    clock = VirtualClock(T0)
    drives = (FcDrive(1, running=True, output_pct=50.0), FcDrive(2, running=True, output_pct=50.0))
    service = Service(
        parse(CONFIG),
        clock=clock,
        transport_factory=lambda _: ScriptedTransport(clock, FcLine(*drives), delay_s=DELAY_S),
    )
    task = asyncio.ensure_future(service.run(install_signals=False))
    await clock.run_until(T0 + 1.0)
    with structlog.testing.capture_logs() as logs:
        service.stop()
        late = Command(action=Action.START, reference_pct=40.0, actor="ops")
        result = await service.execute("a", late)
        await clock.complete(task, within=60.0)
    assert (result.outcome, result.reason) == (Outcome.CANCELLED, "fcmaster is shutting down")
    (audit,) = [e for e in logs if e["event"] == "command.completed" and e["actor"] == "ops"]
    assert audit == {
        "event": "command.completed",
        "log_level": "info",
        "actor": "ops",
        "drive": "a",
        "command": "start",
        "reference_pct": 40.0,
        "frequency_hz": 20.0,
        "outcome": "cancelled",
        "reason": "fcmaster is shutting down",
        "bus": "line1",
    }


async def test_with_hold_a_clients_stop_waiting_for_a_long_ramp_ends_at_the_least_bound() -> None:
    clock = VirtualClock(T0)
    a, b = FcDrive(1, running=True, output_pct=50.0), Ramping(2, clock, ramp_s=60.0)
    service = Service(
        parse(CONFIG.replace("on_shutdown: stop", "on_shutdown: hold")),
        clock=clock,
        transport_factory=lambda _: ScriptedTransport(clock, FcLine(a, b), delay_s=DELAY_S),
    )
    task = asyncio.ensure_future(service.run(install_signals=False))
    await clock.run_until(T0 + 1.0)
    stop = asyncio.ensure_future(service.execute("b", Command(action=Action.STOP, actor="ops")))
    await clock.run_until(T0 + 1.5)  # acknowledged: b ramps down for 30 s
    with structlog.testing.capture_logs() as logs:
        service.stop()
        await clock.complete(task, within=60.0)
    result = await stop
    assert result.outcome is Outcome.UNCONFIRMED
    assert "shut down before the drive's status showed the result" in result.reason
    assert 5.0 <= clock.now() - (T0 + 1.5) < 6.0  # hold: the 5 s bound, not b's ramp
    assert a.running  # left as it was
    assert [e for e in logs if e["event"] == "service.shutdown_commands_timed_out"]
