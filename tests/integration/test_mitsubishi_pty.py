"""The real BusMaster over a real pty against simulated Mitsubishi inverters.

Everything below the master is real: termios, the pty, the simulator's wire timing (12-bit
characters at 8E2, the waiting time, the data check time) and its injected faults. The line
is set up the way the config does it: ``codec_for`` and the protocol's answer delay.
"""

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fcmaster.bus.codecs import codec_for, with_protocol_delay
from fcmaster.bus.commands import Outcome
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock
from fcmaster.protocol.drive import Motion
from fcmaster.protocol.mitsubishi import RESTART_S
from fcmaster.sim.build import build_line
from fcmaster.sim.faults import FaultPlan
from fcmaster.sim.mitsubishi import MitsubishiSimDrive
from fcmaster.sim.pty import PtyServer
from fcmaster.sim.settings import DriveSettings, LineSettings
from fcmaster.transport.serial import SerialTransport
from tests.integration.line_checks import assert_faults_counted_and_no_command_lost
from tests.integration.waiting import wait_for
from tests.orders import orders

LIMIT_S = 40.0
STATIONS = (0, 1, 10, 31)  # 10 is "0A" on the wire, 31 "1F"


@asynccontextmanager
async def line_with_master(
    faults: FaultPlan,
    *,
    drive_faults: dict[int, FaultPlan] | None = None,
    parameters: dict[str, float] | None = None,
) -> AsyncIterator[tuple[PtyServer, BusMaster]]:
    clock = MonotonicClock()
    own = drive_faults or {}
    line = build_line(
        LineSettings(protocol="mitsubishi", baudrate=38400, stopbits=2, faults=faults),
        [(a, DriveSettings(faults=own.get(a), parameters=parameters or {})) for a in STATIONS],
        clock=clock,
    )
    drives = tuple(
        DrivePlan(name=f"d{a}", address=a, control=a == 1, monitor=("H6F", "H70")) for a in STATIONS
    )
    async with asyncio.timeout(LIMIT_S), PtyServer(line, clock=clock) as server:
        plan = LinePlan(
            name="pty", port=server.device, protocol="mitsubishi", baudrate=38400, stopbits=2,
            drives=drives, offline_after=5, probe_interval_s=0.5,
        )  # fmt: skip
        plan = with_protocol_delay(plan)  # as the config derives it
        transport = SerialTransport(plan.port, baudrate=38400, parity="E", stopbits=2)
        codec = codec_for(plan)
        async with BusMaster(plan, codec=codec, transport=transport, clock=clock) as master:
            yield server, master


def sim_drive(server: PtyServer, address: int) -> MitsubishiSimDrive:
    drive = next(d for d in server.line.drives if d.address == address)
    assert isinstance(drive, MitsubishiSimDrive)
    return drive


async def test_polls_commands_and_parameter_access_over_the_pty() -> None:
    async with line_with_master(FaultPlan()) as (server, master):
        await wait_for(lambda: all(s.online for s in master.planner.slots))
        d1, drive = orders(master, "d1"), sim_drive(server, 1)
        started = await d1.start(frequency_hz=30.0)
        assert started.outcome is Outcome.DONE, started.reason
        assert drive.control.set_hz == 30.0  # HED 0BB8 reached the drive
        await wait_for(lambda: abs(drive.motor.frequency_hz - 30.0) < 0.01)
        slot = master.planner.slot("d1")
        await wait_for(lambda: slot.output_hz is not None and slot.output_hz > 29.5)  # 59 % of 50
        changed = await d1.set_reference(frequency_hz=20.0)
        assert changed.outcome is Outcome.DONE, changed.reason
        assert drive.control.set_hz == 20.0
        read = await orders(master, "d31").read("Pr.7")
        assert read.outcome is Outcome.DONE, read.reason
        assert read.value is not None
        assert (read.value.value, read.value.unit) == (5.0, "s")
        written = await d1.write("Pr.8", 2.5)
        assert written.outcome is Outcome.DONE, written.reason
        assert drive.parameters[8] == 25
        monitored = await orders(master, "d10").read("H6F")
        assert monitored.outcome is Outcome.DONE
        assert monitored.value is not None
        assert monitored.value.value == 0.0  # never started
        stopped = await d1.stop()
        assert stopped.outcome is Outcome.DONE
        await wait_for(lambda: not drive.motor.output_on)
        assert master.stats.timeouts == 0
        assert master.stats.checksum_errors == 0


async def test_a_refusal_comes_back_with_the_drives_error_code() -> None:
    async with line_with_master(FaultPlan()) as (server, master):
        await wait_for(lambda: master.planner.slot("d1").online)
        result = await orders(master, "d1").write("Pr.7", 4000.0)  # beyond 3600.0 s
        assert result.outcome is Outcome.REFUSED
        assert result.error is not None
        assert result.error.code == 0xC
        assert "Data range" in result.reason
        assert sim_drive(server, 1).parameters[7] == 50  # unchanged
        beyond = await orders(master, "d1").start(frequency_hz=80.0)  # configured max 50 Hz
        assert beyond.outcome is Outcome.NOT_ALLOWED


async def test_faults_are_counted_and_every_command_ends_once() -> None:
    faults = FaultPlan(drop=0.05, corrupt=0.05, noise=0.05, seed=5)
    # Pr.121 = 9999: garbled requests (collisions with noise) must not trip the drives here
    async with line_with_master(faults, parameters={"Pr.121": 9999.0}) as (server, master):
        await wait_for(lambda: master.stats.replies >= 200, timeout_s=20.0)
        results = await asyncio.gather(
            *(orders(master, f"d{a}").read("Pr.7") for a in STATIONS for _ in range(3))
        )
        counters = server.line.counters
    assert_faults_counted_and_no_command_lost(
        results, master.stats, counters, commands=12, at_least_done=9
    )
    assert all(r.value is not None and r.value.value == 5.0 for r in results if r.ok)


async def test_a_silent_drive_is_demoted_and_comes_back() -> None:
    silent = {10: FaultPlan(silent_periods=((0.5, 2.0),))}
    async with line_with_master(FaultPlan(seed=1), drive_faults=silent) as (_, master):
        slot = master.planner.slot("d10")
        await wait_for(lambda: slot.online is False, timeout_s=5.0)
        assert master.planner.slot("d31").online
        await wait_for(lambda: slot.online is True, timeout_s=8.0)


async def test_reset_restarts_the_drive_and_the_master_waits_for_it() -> None:
    async with line_with_master(FaultPlan(), parameters={"Pr.122": 1.0}) as (server, master):
        d1, drive = orders(master, "d1"), sim_drive(server, 1)
        await wait_for(lambda: master.planner.slot("d1").online)
        assert (await d1.start(frequency_hz=15.0)).ok
        timeouts = master.stats.timeouts
        loop = asyncio.get_running_loop()
        sent = loop.time()
        result = await d1.reset()
        assert result.outcome is Outcome.DONE
        requests = master.stats.drives["d1"].requests
        await asyncio.sleep(RESTART_S / 2)
        assert master.stats.drives["d1"].requests == requests  # left alone while deaf
        await wait_for(lambda: master.stats.drives["d1"].requests > requests, timeout_s=5.0)
        assert loop.time() - sent >= RESTART_S
        assert not drive.motor.output_on  # the reset stopped it …
        intent = master.planner.slot("d1").intent
        assert intent is not None
        assert intent.motion is Motion.STOP  # … and the master will not start it again
        await asyncio.sleep(2.0)  # polls go on: Pr.122 = 1 s never runs out
        assert drive.control.fault is None
        assert master.stats.timeouts == timeouts


async def test_a_command_waiting_for_a_restarting_drive_leaves_the_others_polled() -> None:
    # While d1 restarts, a command for it waits; the other stations are polled meanwhile,
    # in callbacks. Those polls must not be given up to the master's loop for the waiting
    # command (the loop would choose the same poll again and hand it straight back, round
    # and round without a turn of the event loop: nothing on the wire until d1 hears).
    async with line_with_master(FaultPlan(), parameters={"Pr.122": 1.0}) as (_, master):
        d1 = orders(master, "d1")
        await wait_for(lambda: all(s.online for s in master.planner.slots))
        assert (await d1.reset()).outcome is Outcome.DONE
        deaf_from = asyncio.get_running_loop().time()
        read = await d1.read("H6F")  # waits for d1 to hear again
        assert read.outcome is Outcome.DONE, read.reason
        window = (deaf_from + 0.1, deaf_from + RESTART_S - 0.1)
        stations = [
            int(data[1:3], 16)
            for _, direction, at, _, data in master.frames.since(0).frames
            if direction == "tx" and window[0] <= at <= window[1]
        ]
        assert len(stations) >= 10, stations  # tens of polls fit in 0.8 s at 38400
        assert 1 not in stations
        assert set(stations) == {0, 10, 31}
