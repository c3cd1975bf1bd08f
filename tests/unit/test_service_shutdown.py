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

from fcmaster.config import parse
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


async def shut_down(*drives: FcDrive, before_stop: Any = None) -> list[MutableMapping[str, Any]]:
    """Run the service until both drives are online, stop it; the events it logged then."""
    return (await shut_down_service(*drives, before_stop=before_stop))[1]


async def shut_down_service(
    *drives: FcDrive, before_stop: Any = None
) -> tuple[Service, list[MutableMapping[str, Any]]]:
    """:func:`shut_down`, with the service that ran."""
    clock = VirtualClock(T0)
    transports: list[ScriptedTransport] = []

    def scripted(_: object) -> ScriptedTransport:
        transports.append(ScriptedTransport(clock, FcLine(*drives), delay_s=DELAY_S))
        return transports[-1]

    service = Service(parse(CONFIG), clock=clock, transport_factory=scripted)
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
