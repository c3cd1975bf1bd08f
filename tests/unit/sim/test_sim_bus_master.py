"""The real BusMaster against simulated drives through SimTransport, in virtual time.

This is the in-process path the demo and the daemon's ``sim://`` ports take: it shows the
master and the simulator agree on bytes and timing, with and without faults.
"""

from __future__ import annotations

import pytest

from fcmaster.bus.commands import Outcome
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.sim import (
    DriveSettings,
    FaultPlan,
    FcSimDrive,
    LineSettings,
    SimTransport,
    build_line,
)
from tests.fakes import VirtualClock
from tests.orders import orders


def master_on_sim(clock: VirtualClock, faults: FaultPlan) -> tuple[BusMaster, list[FcSimDrive]]:
    line = build_line(
        LineSettings(faults=faults), [(a, DriveSettings()) for a in (1, 2, 3)], clock=clock
    )
    plan = LinePlan(
        name="line1", port="sim://line1",
        drives=tuple(DrivePlan(name=f"d{a}", address=a, control=a == 1) for a in (1, 2, 3)),
    )  # fmt: skip
    master = BusMaster(plan, codec=FcCodec(), transport=SimTransport(line, clock), clock=clock)
    drives = [d for d in line.drives if isinstance(d, FcSimDrive)]
    return master, drives


async def test_master_starts_a_simulated_drive_and_polls_the_rest() -> None:
    clock = VirtualClock()
    master, drives = master_on_sim(clock, FaultPlan())
    async with master:
        result = await clock.complete(orders(master, "d1").start(reference_pct=50.0))
        assert result.ok, result.reason
        await clock.run_for(5.0)
        drives[0].advance(clock.now())
        assert drives[0].motor.frequency_hz == pytest.approx(25.0)
        assert not drives[1].motor.output_on
        stats = master.stats
        assert stats.timeouts == 0
        assert stats.checksum_errors == 0
        assert stats.replies > 100


async def test_master_rides_out_lost_and_corrupted_replies() -> None:
    clock = VirtualClock()
    master, _ = master_on_sim(clock, FaultPlan(drop=0.1, corrupt=0.1, seed=1))
    async with master:
        await clock.run_for(1.0)
        result = await clock.complete(orders(master, "d1").read("3-41"))
        assert result.ok
        assert result.value is not None
        assert result.value.value == 3.0
        await clock.run_for(10.0)
        stats = master.stats
        assert stats.timeouts > 0
        assert stats.checksum_errors > 0
        assert stats.replies > 0.7 * stats.requests


async def test_starts_and_stops_are_done_only_as_the_simulated_drives_show_them() -> None:
    """One FC drive that runs, one in local operation, one whose run enable is missing."""
    clock = VirtualClock()
    settings = {
        1: DriveSettings(),
        2: DriveSettings(local=True),
        3: DriveSettings(interlocked=True),
    }
    line = build_line(LineSettings(), list(settings.items()), clock=clock)
    plan = LinePlan(
        name="line1", port="sim://line1",
        drives=tuple(
            DrivePlan(name=f"d{a}", address=a, control=True, confirm_s=4.0) for a in settings
        ),
    )  # fmt: skip
    master = BusMaster(plan, codec=FcCodec(), transport=SimTransport(line, clock), clock=clock)
    drives = {d.address: d for d in line.drives if isinstance(d, FcSimDrive)}
    async with master:
        await clock.run_for(0.5)
        t0 = clock.now()
        runs = await clock.complete(orders(master, "d1").start(reference_pct=50.0))
        assert runs.outcome is Outcome.DONE
        assert clock.now() - t0 < 1.0  # shown running as soon as its output rises
        local = await clock.complete(orders(master, "d2").start(reference_pct=50.0))
        assert local.outcome is Outcome.UNCONFIRMED
        assert "local operation" in local.reason
        t0 = clock.now()
        ignored = await clock.complete(orders(master, "d3").start(reference_pct=50.0))
        assert ignored.outcome is Outcome.UNCONFIRMED
        assert ignored.reason.startswith("not running after 4 s: the drive reports ready")
        assert 4.0 <= clock.now() - t0 < 4.5
        await clock.run_for(5.0)  # d1 at speed
        t0 = clock.now()
        stopped = await clock.complete(orders(master, "d1").stop())
        assert stopped.outcome is Outcome.DONE
        drives[1].advance(clock.now())
        assert drives[1].motor.frequency_hz == 0.0
        ramp_down_s = drives[1].parameters.value(342) * 25.0 / 50.0  # 3-42 is 0 to 3-03
        assert clock.now() - t0 >= ramp_down_s - 0.2  # done once it stood, not when acknowledged
