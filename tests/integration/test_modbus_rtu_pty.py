"""The real BusMaster and SerialTransport against simulated Modbus RTU drives on a pty.

One simulated drive per built-in profile, each enforcing its family's state machine, on
one line (a line may mix profiles). Everything below the master is real: the codec the
line's plan chooses, termios, the pty, the simulator's wire timing. Each test waits for
conditions, never for times.
"""

from __future__ import annotations

import asyncio
import dataclasses
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Any

import pytest

from fcmaster.bus.codecs import codec_for
from fcmaster.bus.commands import Outcome
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock
from fcmaster.hub import Hub
from fcmaster.protocol.modbus_rtu.profiles import BUILT_IN
from fcmaster.sim.build import build_line
from fcmaster.sim.modbus_rtu import ModbusSimDrive
from fcmaster.sim.modbus_rtu.machine import State
from fcmaster.sim.pty import PtyServer
from fcmaster.sim.settings import DriveSettings, LineSettings
from fcmaster.state import FleetState
from fcmaster.transport.serial import SerialTransport
from tests.integration.waiting import wait_for
from tests.orders import orders

LIMIT_S = 60.0
BAUDRATE = 19200
PROFILES = tuple(BUILT_IN)  # address 1 + i follows PROFILES[i]
RAMPS = {"ramp_up_s": 0.5, "ramp_down_s": 0.5}
# A fault each profile's drive trips with in the test, and the text the state must show.
TRIPS = {
    "abb-drives": (2310, "Overcurrent"),
    "sinamics-v20": (4, "F4 Inverter overtemperature"),
    "altivar-cia402": (9, "OCF Overcurrent"),
    "yaskawa-memobus": (0x07, "oC Overcurrent"),
    "danfoss-fc-modbus": (5, "Over current"),
}


@dataclasses.dataclass
class Line:
    server: PtyServer
    master: BusMaster
    fleet: FleetState
    hub: Hub

    async def until(self, condition: Callable[[], object], timeout_s: float = 15.0) -> None:
        await self.hub.wait_for(condition, timeout_s=timeout_s)

    def drive(self, address: int) -> ModbusSimDrive:
        found = next(d for d in self.server.line.drives if d.address == address)
        assert isinstance(found, ModbusSimDrive)
        return found

    def state(self, name: str) -> dict[str, Any]:
        found = self.fleet.get("mb", name)
        assert found is not None
        return found.to_json()


@asynccontextmanager
async def modbus_line() -> AsyncIterator[Line]:
    clock = MonotonicClock()
    addresses = range(1, len(PROFILES) + 1)
    line = build_line(
        LineSettings(protocol="modbus-rtu", baudrate=BAUDRATE, parity="E"),
        [
            (a, DriveSettings(response_delay_s=0.002, parameters=RAMPS, profile=PROFILES[a - 1]))
            for a in addresses
        ],
        clock=clock,
    )
    drives = tuple(
        DrivePlan(
            name=PROFILES[a - 1], address=a, control=True, nominal_frequency_hz=50.0,
            max_frequency_hz=50.0, profile=BUILT_IN[PROFILES[a - 1]], confirm_s=5.0,
        )
        for a in addresses
    )  # fmt: skip
    async with asyncio.timeout(LIMIT_S), PtyServer(line, clock=clock) as server:
        plan = LinePlan(
            name="mb", port=server.device, protocol="modbus-rtu", baudrate=BAUDRATE,
            parity="E", drives=drives, offline_after=5, probe_interval_s=0.5,
            response_delay_s=0.002,
        )  # fmt: skip
        hub = Hub()
        fleet = FleetState((plan,), emit=hub.publish, clock=clock)
        transport = SerialTransport(plan.port, baudrate=BAUDRATE, parity=plan.parity)
        async with BusMaster(
            plan, codec=codec_for(plan), transport=transport, clock=clock, observer=fleet
        ) as master:
            yield Line(server, master, fleet, hub)


@pytest.mark.parametrize("profile", PROFILES)
async def test_start_reference_stop_and_a_trip_with_its_text(profile: str) -> None:
    address = PROFILES.index(profile) + 1
    async with modbus_line() as line:
        await wait_for(lambda: line.master.planner.slot(profile).online)
        sim, drive = line.drive(address), orders(line.master, profile)
        assert sim.profile.name == profile

        started = await drive.start(frequency_hz=30.0)
        assert started.outcome is Outcome.DONE, started.reason
        assert sim.machine.state is State.OPERATION_ENABLED
        await line.until(lambda: line.state(profile)["running"] is True)
        await line.until(
            lambda: line.state(profile)["output_frequency_hz"] == pytest.approx(30.0, abs=0.05)
        )
        assert sim.motor.frequency_hz == pytest.approx(30.0, abs=0.05)

        stopped = await drive.stop()
        assert stopped.outcome is Outcome.DONE, stopped.reason
        await line.until(lambda: line.state(profile)["running"] is False)
        await wait_for(lambda: not sim.motor.output_on)

        code, text = TRIPS[profile]
        sim.raise_fault(code, MonotonicClock().now())
        await line.until(lambda: line.state(profile)["fault"] is True)
        await line.until(lambda: line.state(profile)["alarms"] == [{"code": code, "text": text}])
        sim.clear_fault(MonotonicClock().now())
        reset = await drive.reset()
        assert reset.outcome is Outcome.DONE, reset.reason
        await line.until(lambda: line.state(profile)["fault"] is False)
        assert not sim.motor.output_on  # a reset never restarts the motor
