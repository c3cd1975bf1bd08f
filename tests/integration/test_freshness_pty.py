"""Honest freshness: a drive state never shows a value under a newer time than its reading.

Mitsubishi and ENC read the output frequency in an exchange of its own, apart from the
status. Each protocol's line runs here for real (simulator on a pty, SerialTransport,
BusMaster) while the drive ramps up and down; every reply the master reports is recorded
with the frequency it carried, and every state the fleet publishes must show a frequency
that a reply carried at exactly ``output_frequency_updated_at`` — never an older reading
under a newer time.
"""

from __future__ import annotations

import asyncio
import dataclasses
from dataclasses import dataclass, field

import pytest

from fcmaster.bus.codecs import codec_for, with_protocol_delay
from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock
from fcmaster.protocol.codec import Reply
from fcmaster.protocol.drive import ControlIntent
from fcmaster.sim.build import build_line
from fcmaster.sim.faults import FaultPlan
from fcmaster.sim.pty import PtyServer
from fcmaster.sim.settings import DriveSettings, LineSettings
from fcmaster.state import DriveState, DriveUpdated, Event, FleetState
from fcmaster.transport.serial import SerialTransport
from tests.fakes import WallShiftedClock
from tests.integration.waiting import wait_for
from tests.orders import orders

LIMIT_S = 40.0
WALL0 = 1_800_000_000.0  # the fleet's wall clock is this plus monotonic time


def _drive(monitor: tuple[str, ...]) -> DrivePlan:
    return DrivePlan(
        name="d1", address=1, control=True, nominal_frequency_hz=50.0, max_frequency_hz=50.0,
        monitor=monitor,
    )  # fmt: skip


# protocol → (simulated line, its ramp parameters, the master's line with its port left out)
LINES = {
    "mitsubishi": (
        LineSettings(protocol="mitsubishi", baudrate=38400, stopbits=2, faults=FaultPlan()),
        {"Pr.7": 1.0, "Pr.8": 1.0},
        LinePlan(
            name="l", port="", protocol="mitsubishi", baudrate=38400, stopbits=2,
            drives=(_drive(("H6F", "H70")),), offline_after=5, probe_interval_s=0.5,
        ),
    ),
    "enc": (
        LineSettings(protocol="enc", baudrate=19200, parity="N", faults=FaultPlan()),
        {"F0.08": 1.0, "F0.09": 1.0},
        LinePlan(
            name="l", port="", protocol="enc", baudrate=19200, parity="N",
            drives=(_drive(("running_frequency", "output_current")),), offline_after=5,
            probe_interval_s=0.5, response_delay_s=0.005,
        ),
    ),
}  # fmt: skip


@dataclass
class Recorder:
    """A BusObserver in front of the fleet: keeps every frequency reading by its wall time."""

    fleet: FleetState
    readings: dict[float, float] = field(default_factory=dict)

    def drive_replied(
        self, bus: str, drive: DrivePlan, reply: Reply, at: float, commanded: ControlIntent | None
    ) -> None:
        if reply.output_frequency_hz is not None:
            self.readings[WALL0 + at] = abs(reply.output_frequency_hz)
        self.fleet.drive_replied(bus, drive, reply, at, commanded)

    def drive_availability(self, bus: str, drive: DrivePlan, online: bool, at: float) -> None:
        self.fleet.drive_availability(bus, drive, online, at)

    def line_availability(self, bus: str, up: bool, reason: str, at: float) -> None:
        self.fleet.line_availability(bus, up, reason, at)

    def command_completed(
        self, bus: str, drive: str, command: Command, result: CommandResult
    ) -> None:
        self.fleet.command_completed(bus, drive, command, result)


@pytest.mark.parametrize("protocol", sorted(LINES))
async def test_no_state_shows_an_old_frequency_under_a_new_time(protocol: str) -> None:
    settings, ramps, template = LINES[protocol]
    clock: MonotonicClock = WallShiftedClock(lambda: WALL0 + clock.now())
    line = build_line(
        settings, [(1, DriveSettings(response_delay_s=0.005, parameters=ramps))], clock=clock
    )
    published: list[DriveState] = []

    def keep(event: Event) -> None:
        if isinstance(event, DriveUpdated):
            published.append(event.state)

    async with asyncio.timeout(LIMIT_S), PtyServer(line, clock=clock) as server:
        plan = with_protocol_delay(dataclasses.replace(template, port=server.device))
        fleet = FleetState((plan,), emit=keep, clock=clock)
        recorder = Recorder(fleet)
        transport = SerialTransport(
            plan.port, baudrate=plan.baudrate, parity=plan.parity, stopbits=plan.stopbits
        )
        async with BusMaster(
            plan, codec=codec_for(plan), transport=transport, clock=clock, observer=recorder
        ) as master:
            await wait_for(lambda: master.planner.slot("d1").online)
            handle = orders(master, "d1")
            for order in (handle.start(frequency_hz=45.0), handle.set_reference(frequency_hz=5.0)):
                result = await order
                assert result.outcome is Outcome.DONE, result.reason
                await asyncio.sleep(1.2)  # through the ramp, while status and frequency alternate
            assert (await handle.stop()).outcome is Outcome.DONE
            await asyncio.sleep(0.5)

    with_frequency = [s for s in published if s.output_frequency_hz is not None]
    assert len({s.output_frequency_hz for s in with_frequency}) > 5  # it did ramp
    for state in with_frequency:
        read_at = state.output_frequency_updated_at
        assert read_at is not None
        assert state.updated_at is not None
        assert read_at <= state.updated_at
        # the frequency shown is the one read at the time shown, not a later or earlier one
        # within 0.1 ms: the fleet reads the clock twice to turn a reply's time into wall time
        # (microseconds apart), and replies on this line are milliseconds apart
        (read,) = [hz for t, hz in recorder.readings.items() if abs(t - read_at) < 1e-4]
        assert read == state.output_frequency_hz
    # and the two times do part: the status arrived in an exchange of its own
    assert any(s.output_frequency_updated_at != s.updated_at for s in with_frequency)
