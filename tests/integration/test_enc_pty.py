"""The real BusMaster and SerialTransport against simulated ENC drives on a pseudo-terminal.

Everything below the master is real: the codec chosen by the line's config, termios, the
pty, the simulator's wire timing and its injected faults. Timing is only bounded from
below (nothing is asserted about how fast); each test is bounded by a timeout.
"""

from __future__ import annotations

import asyncio
import dataclasses
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Any

from fcmaster.bus.codecs import codec_for
from fcmaster.bus.commands import Outcome
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock
from fcmaster.hub import Hub
from fcmaster.protocol.enc import StateWord
from fcmaster.sim.build import build_line
from fcmaster.sim.enc import EncSimDrive
from fcmaster.sim.faults import FaultPlan
from fcmaster.sim.pty import PtyServer
from fcmaster.sim.settings import DriveSettings, LineSettings
from fcmaster.state import FleetState
from fcmaster.transport.serial import SerialTransport
from tests.integration.line_checks import assert_faults_counted_and_no_command_lost
from tests.integration.waiting import wait_for
from tests.orders import orders

LIMIT_S = 30.0
ADDRESSES = (1, 2, 3)
BAUDRATE = 19200
ENCODED = ("address", "response", "fault")  # the ENC line keys <what>_encoding
RAMPS = {"F0.08": 1.0, "F0.09": 1.0}  # 0 to 50 Hz in a second, so tests need not wait long


@dataclasses.dataclass
class Line:
    server: PtyServer
    master: BusMaster
    fleet: FleetState
    hub: Hub

    async def until(self, condition: Callable[[], object], timeout_s: float = 10.0) -> None:
        """Wait until ``condition`` holds, checked at each change the fleet publishes."""
        await self.hub.wait_for(condition, timeout_s=timeout_s)

    def drive(self, address: int) -> EncSimDrive:
        found = next(d for d in self.server.line.drives if d.address == address)
        assert isinstance(found, EncSimDrive)
        return found


@asynccontextmanager
async def enc_line(
    faults: FaultPlan | None = None,
    *,
    settings: dict[int, DriveSettings] | None = None,
    encoding: str = "hex",
) -> AsyncIterator[Line]:
    clock = MonotonicClock()
    own = settings or {}
    line = build_line(
        LineSettings(
            protocol="enc", baudrate=BAUDRATE, parity="N", faults=faults or FaultPlan(),
            protocol_options=tuple((f"{n}_encoding", encoding) for n in ENCODED),
        ),
        [
            (a, own.get(a, DriveSettings(response_delay_s=0.005, parameters=RAMPS)))
            for a in ADDRESSES
        ],
        clock=clock,
    )  # fmt: skip
    drives = tuple(
        DrivePlan(
            name=f"d{a}", address=a, control=a == 1, nominal_frequency_hz=50.0,
            max_frequency_hz=50.0, monitor=("running_frequency", "output_current"),
        )
        for a in ADDRESSES
    )  # fmt: skip
    async with asyncio.timeout(LIMIT_S), PtyServer(line, clock=clock) as server:
        plan = LinePlan(
            name="enc", port=server.device, protocol="enc", baudrate=BAUDRATE, parity="N",
            drives=drives, offline_after=5, probe_interval_s=0.5, response_delay_s=0.005,
            address_encoding=encoding, response_encoding=encoding, fault_encoding=encoding,
        )  # fmt: skip
        hub = Hub()
        fleet = FleetState((plan,), emit=hub.publish, clock=clock)
        transport = SerialTransport(plan.port, baudrate=BAUDRATE, parity=plan.parity)
        async with BusMaster(
            plan, codec=codec_for(plan), transport=transport, clock=clock, observer=fleet
        ) as master:
            yield Line(server, master, fleet, hub)


def state(line: Line, name: str) -> dict[str, Any]:
    found = line.fleet.get("enc", name)
    assert found is not None
    return found.to_json()


async def test_polls_refresh_state_and_frequency_of_every_drive() -> None:
    running = DriveSettings(response_delay_s=0.005, parameters=RAMPS, running_hz=30.0)
    async with enc_line(settings={2: running}) as line:
        await wait_for(lambda: all(s.online for s in line.master.planner.slots))
        await line.until(lambda: state(line, "d2")["output_frequency_hz"] is not None)
        d2 = state(line, "d2")
        assert d2["running"] is True
        assert d2["protocol"] == "enc"
        assert d2["output_frequency_hz"] == 30.0
        assert d2["status_word"] == StateWord.RUNNING | StateWord.NORMAL_RUN
        await wait_for(lambda: "11/0003" in state(line, "d2")["values"])
        assert state(line, "d1")["running"] is False
        assert line.master.stats.timeouts == 0
        assert line.master.stats.checksum_errors == 0


async def test_start_with_frequency_stop_emergency_stop_and_reset() -> None:
    async with enc_line() as line:
        await wait_for(lambda: line.master.planner.slot("d1").online)
        d1, sim = orders(line.master, "d1"), line.drive(1)
        assert (await d1.start(frequency_hz=40.0)).outcome is Outcome.DONE
        await line.until(lambda: state(line, "d1")["output_frequency_hz"] == 40.0)
        assert state(line, "d1")["running"] is True
        assert (await d1.stop()).outcome is Outcome.DONE
        await line.until(lambda: state(line, "d1")["running"] is False)

        assert (await d1.start(frequency_hz=25.0)).outcome is Outcome.DONE
        await wait_for(lambda: sim.motor.frequency_hz > 20.0)
        # The urgent stop is ENC's emergency stop (12/000D): the output is cut at once.
        assert (await d1.quick_stop()).outcome is Outcome.DONE
        assert sim.control.emergency
        assert not sim.motor.output_on

        sim.control.raise_fault(10, MonotonicClock().now())  # inverter overheat
        await line.until(lambda: state(line, "d1")["fault"] is True)
        assert state(line, "d1")["alarms"] == [{"code": 10, "text": "Inverter overheat"}]
        refused = await d1.reset()
        assert refused.outcome is Outcome.REFUSED  # the cause is still there: response 30
        assert refused.error is not None
        assert refused.error.code == 30
        sim.control.clear_fault(10, MonotonicClock().now())
        assert (await d1.reset()).outcome is Outcome.DONE
        await line.until(lambda: state(line, "d1")["fault"] is False)
        assert state(line, "d1")["alarms"] == []
        assert not sim.motor.output_on  # a reset never restarts the motor


async def test_read_write_and_a_refusal() -> None:
    async with enc_line() as line:
        await wait_for(lambda: line.master.planner.slot("d1").online)
        d1 = orders(line.master, "d1")
        written = await d1.write("F0.08", 2.5)
        assert written.outcome is Outcome.DONE
        read = await d1.read("F0.08")
        assert read.outcome is Outcome.DONE
        assert read.value is not None
        assert (read.value.value, read.value.unit, read.value.raw) == (2.5, "s", 25)
        assert line.drive(1).parameters.value(0x0008) == 2.5

        current = await orders(line.master, "d2").read("output_current")
        assert current.outcome is Outcome.DONE

        # F2.17 takes 0-200 ms: the drive refuses 300 with response 30, stored nothing.
        refused = await d1.write("F2.17", 300)
        assert refused.outcome is Outcome.REFUSED
        assert refused.error is not None
        assert refused.error.code == 30
        assert line.drive(1).response_delay_s == 0.005

        # Beyond the configured maximum never reaches the wire.
        beyond = await d1.start(frequency_hz=55.0)
        assert beyond.outcome is Outcome.NOT_ALLOWED


async def test_a_drive_in_local_operation_refuses_bus_control() -> None:
    local = DriveSettings(response_delay_s=0.005, parameters=RAMPS, local=True)
    async with enc_line(settings={1: local}) as line:
        await wait_for(lambda: line.master.planner.slot("d1").online)
        result = await orders(line.master, "d1").start(frequency_hz=20.0)
        assert result.outcome is Outcome.REFUSED
        assert result.error is not None
        assert result.error.code == 30
        assert not line.drive(1).motor.output_on


async def test_decimal_encodings_end_to_end() -> None:
    async with enc_line(encoding="decimal") as line:
        await wait_for(lambda: all(s.online for s in line.master.planner.slots))
        line.drive(3).control.raise_fault(16, MonotonicClock().now())
        await line.until(lambda: state(line, "d3")["fault"] is True)
        assert state(line, "d3")["alarms"] == [{"code": 16, "text": "RS-485 communication fault"}]


async def test_bad_checksums_and_timeouts_are_counted_and_recovered() -> None:
    faults = FaultPlan(drop=0.05, corrupt=0.05, noise=0.05, seed=3)
    async with enc_line(faults) as line:
        master = line.master
        # 19200 baud ASCII: ~40 replies/s, so 150 give ~15 injected faults to ride out.
        await wait_for(lambda: master.stats.replies >= 150, timeout_s=30.0)
        results = await asyncio.gather(
            *(
                orders(master, f"d{a}").read("running_frequency")
                for a in ADDRESSES
                for _ in range(5)
            )
        )
        counters = line.server.line.counters
        assert all(s.online for s in master.planner.slots)  # nobody lost for good
    assert_faults_counted_and_no_command_lost(
        results, master.stats, counters, commands=15, at_least_done=12
    )
    assert master.stats.malformed == 0


async def test_a_silent_drive_is_demoted_probed_and_promoted_again() -> None:
    silent = FaultPlan(silent_periods=((0.5, 2.0),))
    settings = {2: DriveSettings(response_delay_s=0.005, parameters=RAMPS, faults=silent)}
    async with enc_line(FaultPlan(seed=1), settings=settings) as line:
        slot = line.master.planner.slot("d2")
        await wait_for(lambda: slot.online is False, timeout_s=5.0)
        assert line.master.planner.slot("d3").online  # the others are still polled
        await wait_for(lambda: slot.online is True, timeout_s=8.0)
