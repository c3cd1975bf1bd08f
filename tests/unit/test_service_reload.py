"""A reload of a running service in virtual time: what the drives that stay and go are told.

A Service runs one scripted FC line of bus-controlled drives, all running. A reload that
removes one leaves it as ``on_shutdown`` says (``stop``: a stop first; ``hold``: nothing more
is sent to it), and the drive that stays is told to run on in every telegram.
"""

from __future__ import annotations

import asyncio

import pytest

from fcmaster.config import Config, parse
from fcmaster.service import Service
from tests.fakes import ScriptedTransport, VirtualClock
from tests.unit.bus.bench import DELAY_S, STOP_WORD, T0
from tests.unit.bus.fcdrive import FcDrive, FcLine, default_parameters

CONFIG = """
buses:
  - name: line1
    port: /dev/ttyTEST
    baudrate: 19200
    drives:
      - {{name: a, address: 1, control: bus}}
{b}
on_shutdown: {on_shutdown}
"""
B = "      - {name: b, address: 2, control: bus}"


def _config(*, b: bool, on_shutdown: str) -> Config:
    return parse(CONFIG.format(b=B if b else "", on_shutdown=on_shutdown))


@pytest.mark.parametrize("on_shutdown", ["stop", "hold"])
async def test_a_removed_bus_drive_is_left_as_on_shutdown_says_and_the_other_runs_on(
    on_shutdown: str,
) -> None:
    clock = VirtualClock(T0)
    a, b = FcDrive(1, running=True, output_pct=50.0), FcDrive(2, running=True, output_pct=50.0)
    line = FcLine(a, b)
    service = Service(
        _config(b=True, on_shutdown=on_shutdown),
        clock=clock,
        transport_factory=lambda _: ScriptedTransport(clock, line, delay_s=DELAY_S),
        load=lambda _: _config(b=False, on_shutdown=on_shutdown),
    )
    task = asyncio.ensure_future(service.run(install_signals=False))
    await clock.run_until(T0 + 1.0)
    assert all(state.online for state in service.fleet.snapshot())
    heard_a, heard_b = len(a.received), len(b.received)
    reload = asyncio.ensure_future(service.reloader.reload())
    last = await clock.complete(reload, within=30.0)
    assert last["outcome"] == "applied"
    assert last["changes"] == ["line1: drive b removed"]
    after_b = len(b.received)
    await clock.run_for(2.0)
    assert len(b.received) == after_b  # no longer polled
    told_b = [t.pcd1 for t in b.received[heard_b:]]
    if on_shutdown == "stop":
        assert told_b[-1] == STOP_WORD
        assert not b.running
    else:
        assert STOP_WORD not in told_b
        assert b.running  # its own control-word timeout acts, not the gateway
    told_a = [t.pcd1 for t in a.received[heard_a:]]
    assert len(told_a) > 10
    assert STOP_WORD not in told_a  # never jolted
    assert a.running
    assert [s.name for s in service.fleet.snapshot()] == ["a"]
    service.stop()
    await clock.complete(task, within=60.0)


async def test_a_drive_a_reload_adds_is_judged_by_its_own_takeover_not_the_daemons_age() -> None:
    # The watchdog verdict counts what taking a drive over cost it: for a drive a reload
    # adds ten minutes later that is the time from the reload to its first telegram.
    clock = VirtualClock(T0)
    # b's own watchdog: 8-03 = 2.0 s, 8-04 = [2] stop; ok for the line's round
    watched = FcDrive(2, parameters=default_parameters() | {803: 20, 804: 2})
    line = FcLine(FcDrive(1, running=True, output_pct=50.0), watched)
    with_b = _config(b=True, on_shutdown="hold")
    service = Service(
        _config(b=False, on_shutdown="hold"),
        clock=clock,
        transport_factory=lambda _: ScriptedTransport(clock, line, delay_s=DELAY_S),
        load=lambda _: with_b,
    )
    task = asyncio.ensure_future(service.run(install_signals=False))
    await clock.run_until(T0 + 600.0)
    reload = asyncio.ensure_future(service.reloader.reload())
    reloaded_at = clock.now()
    assert (await clock.complete(reload, within=30.0))["outcome"] == "applied"
    await clock.run_for(10.0)
    b = service.fleet.get("line1", "b")
    assert b is not None
    assert b.watchdog is not None
    assert b.watchdog.restart_gap_s is not None
    assert b.watchdog.restart_gap_s < 1.0, (b.watchdog, reloaded_at - T0)
    assert (b.watchdog.timeout_s, b.watchdog.verdict.value) == (2.0, "ok")
    service.stop()
    await clock.complete(task, within=60.0)
