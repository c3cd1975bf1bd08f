"""The real BusMaster against simulated Mitsubishi drives through SimTransport, virtual time.

The master, the Mitsubishi codec and the simulated inverter must agree on every byte and
every deadline: two-transaction parameter access, the reset that gets no reply, and the
drive's own communication check tripping it once the master goes away.
"""

from __future__ import annotations

import dataclasses

import pytest

from fcmaster.bus.codecs import codec_for, with_protocol_delay
from fcmaster.bus.commands import Outcome
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.protocol.drive import Motion
from fcmaster.protocol.mitsubishi import RESTART_S, StatusBits
from fcmaster.sim import (
    DriveSettings,
    FaultPlan,
    LineSettings,
    MitsubishiSimDrive,
    SimTransport,
    build_line,
)
from tests.fakes import VirtualClock
from tests.orders import orders

PLAN = LinePlan(
    name="line1", port="sim://line1", protocol="mitsubishi", stopbits=2,
    drives=(DrivePlan(name="d0", address=0, control=True), DrivePlan(name="d5", address=5)),
)  # fmt: skip


def master_on_sim(
    clock: VirtualClock, faults: FaultPlan | None = None, retries: int = 1, **parameters: float
) -> tuple[BusMaster, list[MitsubishiSimDrive]]:
    settings = DriveSettings(parameters={k.replace("_", "."): v for k, v in parameters.items()})
    line = build_line(
        LineSettings(protocol="mitsubishi", stopbits=2, faults=faults or FaultPlan()),
        [(0, settings), (5, settings)],
        clock=clock,
    )
    plan = with_protocol_delay(dataclasses.replace(PLAN, retries=retries))  # as the config does
    master = BusMaster(
        plan, codec=codec_for(plan), transport=SimTransport(line, clock), clock=clock
    )
    return master, [d for d in line.drives if isinstance(d, MitsubishiSimDrive)]


async def test_start_read_write_and_stop_through_the_master() -> None:
    clock = VirtualClock()
    master, drives = master_on_sim(clock)
    async with master:
        d0 = orders(master, "d0")
        assert (await clock.complete(d0.start(frequency_hz=30.0))).ok
        await clock.run_for(5.0)
        drives[0].advance(clock.now())
        assert drives[0].motor.frequency_hz == pytest.approx(30.0)
        written = await clock.complete(d0.write("Pr.8", 2.5))  # ramps may change running
        assert written.ok, written.reason
        assert written.value is not None
        assert written.value.value == 2.5
        refused = await clock.complete(d0.write("Pr.1", 60.0))  # the maximum may not
        assert refused.outcome is Outcome.REFUSED
        assert refused.error is not None
        assert refused.error.code == 0xA  # mode error
        read = await clock.complete(orders(master, "d5").read("Pr.7"))
        assert read.ok, read.reason
        assert read.value is not None
        assert (read.value.value, read.value.unit) == (5.0, "s")
        assert (await clock.complete(d0.stop())).ok
        await clock.run_for(6.0)
        drives[0].advance(clock.now())
        assert not drives[0].motor.output_on
        assert master.stats.timeouts == 0


async def test_reset_is_sent_once_and_the_drive_is_left_alone_while_it_restarts() -> None:
    clock = VirtualClock()
    master, drives = master_on_sim(clock, Pr_122=0.5)
    async with master:
        d0 = orders(master, "d0")
        assert (await clock.complete(d0.start(frequency_hz=20.0))).ok
        await clock.run_for(3.0)
        before = master.stats.drives["d0"].requests
        timeouts = master.stats.timeouts
        result = await clock.complete(d0.reset())
        assert result.outcome is Outcome.DONE
        await clock.run_for(RESTART_S * 0.9)
        # Nothing went to d0 while it restarted; d5 was polled all the while.
        assert master.stats.drives["d0"].requests == before + 1
        assert master.stats.drives["d5"].replies > 10
        await clock.run_for(RESTART_S * 0.2)  # just past the restart: d0 is polled again
        assert master.stats.drives["d0"].requests > before + 1
        await clock.run_for(2.0)
        assert master.stats.timeouts == timeouts  # it was never asked while deaf
        intent = master.planner.slot("d0").intent
        assert intent is not None
        assert intent.motion is Motion.STOP  # a reset never restarts the motor
        drives[0].advance(clock.now())
        assert not drives[0].motor.output_on


async def test_the_drives_watchdog_trips_it_once_the_master_is_gone() -> None:
    clock = VirtualClock()
    master, drives = master_on_sim(clock, Pr_122=1.0)
    async with master:
        assert (await clock.complete(orders(master, "d0").start(frequency_hz=25.0))).ok
        await clock.run_for(3.0)
        drives[0].advance(clock.now())
        assert drives[0].control.fault is None  # fed by the polls while the master runs
    await clock.run_for(2.0)  # the master is gone
    drives[0].advance(clock.now())
    assert drives[0].control.fault == 0xB1  # E.PUE
    assert not drives[0].motor.output_on
    assert drives[0].control.status(extended=True) & StatusBits.FAULT
    drives[1].advance(clock.now())
    assert drives[1].control.fault == 0xB1  # only monitored, but its check ran out as well


async def test_lost_and_corrupted_replies_are_counted_and_ridden_out() -> None:
    clock = VirtualClock()
    # A read is two exchanges (page select, read); with a fifth of the replies lost or
    # corrupted, one retry for both is not enough to ride it out.
    faults = FaultPlan(drop=0.1, corrupt=0.1, seed=3)
    master, _ = master_on_sim(clock, faults, retries=3, Pr_121=9999)
    async with master:
        await clock.run_for(1.0)
        read = await clock.complete(orders(master, "d5").read("Pr.7"))
        assert read.ok, read.reason
        await clock.run_for(10.0)
        stats = master.stats
        assert stats.timeouts > 0
        assert stats.checksum_errors > 0
        assert stats.replies > 0.7 * stats.requests
