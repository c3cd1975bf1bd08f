"""fcmaster against an independent Modbus RTU server: pymodbus's, on a pseudo-terminal.

pymodbus (a kept library, not ours) serves a register map over RTU; the daemon's master,
built from a config file whose drive names a user profile file, polls and commands it. The
server records every write: each must be one of the profile's words, in its order. The
server's only behaviour beyond storing registers is the test's own small CiA 402 model, so
that a start can be confirmed by the status word as on a real drive.
"""

from __future__ import annotations

import asyncio
import os
import tty
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from pymodbus import FramerType
from pymodbus.server import ModbusSerialServer
from pymodbus.simulator import DataType, SimData, SimDevice

from fcmaster.bus.codecs import codec_for
from fcmaster.bus.commands import Outcome
from fcmaster.bus.master import BusMaster
from fcmaster.clock import MonotonicClock
from fcmaster.config import load
from fcmaster.hub import Hub
from fcmaster.state import FleetState
from fcmaster.transport.serial import SerialTransport
from tests.integration.waiting import wait_for
from tests.orders import orders

UNIT = 7
CONTROL, REFERENCE, STATUS, FREQUENCY, FAULT, CURRENT = 100, 101, 200, 201, 202, 300
PROFILE = f"""
name: peer-vfd
state_machine: cia402
registers:
  control: {{address: {CONTROL}}}
  reference: {{address: {REFERENCE}, scale: 0.01, unit: Hz}}
  status: {{address: {STATUS}}}
  output_frequency: {{address: {FREQUENCY}, scale: 0.01, unit: Hz, signed: true}}
  fault_code: {{address: {FAULT}}}
commands:
  start: [0x06, 0x07, 0x0F]
  stop: [0x07]
  coast: [0x00]
  quick_stop: [0x02]
  reset: [0x80, 0x00]
status_bits: {{ready: 0, running: 2, fault: 3, warning: 7, remote: 9, at_reference: 10}}
faults: {{16: "Drive overheat"}}
values: [{{name: "Motor current", address: {CURRENT}, input: true, scale: 0.1, unit: A}}]
"""
# The test's CiA 402 model: (control word, status word before) → status word after; a word
# out of sequence changes nothing (remote bit 9 always set).
DISABLED, READY, SWITCHED_ON, ENABLED = 0x0240, 0x0221, 0x0223, 0x0627
TRANSITIONS = {
    (0x06, DISABLED): READY,
    (0x06, SWITCHED_ON): READY,
    (0x07, READY): SWITCHED_ON,
    (0x07, ENABLED): SWITCHED_ON,
    (0x0F, SWITCHED_ON): ENABLED,
}


@dataclass
class Peer:
    writes: list[tuple[int, int]] = field(default_factory=list)  # (register, value)

    async def action(
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        current_registers: list[int],
        set_values: list[int] | list[bool] | None,
    ) -> None:
        if set_values is None:
            return
        values = [int(v) for v in set_values]
        self.writes += [(address + i, v) for i, v in enumerate(values)]
        if address == CONTROL:
            before = current_registers[STATUS - start_address]
            after = TRANSITIONS.get((values[0], before), before)
            if values[0] in (0x00, 0x02):
                after = DISABLED
            current_registers[STATUS - start_address] = after
            reference = current_registers[REFERENCE - start_address]
            current_registers[FREQUENCY - start_address] = reference if after == ENABLED else 0

    def control_words(self) -> list[int]:
        return [v for r, v in self.writes if r == CONTROL]


@dataclass
class Line:
    peer: Peer
    master: BusMaster
    fleet: FleetState
    hub: Hub

    def state(self) -> dict[str, Any]:
        found = self.fleet.get("peer", "vfd")
        assert found is not None
        return found.to_json()


def _pty_pair() -> tuple[int, int, str, str]:
    """Two pseudo-terminals joined back to back: (masters…, devices…)."""
    m1, s1 = os.openpty()
    m2, s2 = os.openpty()
    for fd in (s1, s2):
        tty.setraw(fd)
    return m1, m2, os.ttyname(s1), os.ttyname(s2)


@asynccontextmanager
async def peer_line(tmp_path: Path) -> AsyncIterator[Line]:
    m1, m2, server_device, master_device = _pty_pair()
    loop = asyncio.get_running_loop()

    def forward(src: int, dst: int) -> None:
        with suppress(OSError):
            os.write(dst, os.read(src, 4096))

    loop.add_reader(m1, forward, m1, m2)
    loop.add_reader(m2, forward, m2, m1)
    peer = Peer()
    registers = [
        SimData(address=CONTROL, values=[0, 0], datatype=DataType.REGISTERS),
        SimData(address=STATUS, values=[0x0240, 0, 0], datatype=DataType.REGISTERS),
        SimData(address=CURRENT, values=[123], datatype=DataType.REGISTERS),
    ]
    server = ModbusSerialServer(
        SimDevice(id=UNIT, simdata=registers, action=peer.action),
        port=server_device, baudrate=19200, parity="N", framer=FramerType.RTU,
    )  # fmt: skip
    serving = asyncio.create_task(server.serve_forever())
    (tmp_path / "peer-vfd.yaml").write_text(PROFILE, encoding="utf-8")
    config = tmp_path / "fcmaster.yaml"
    config.write_text(
        f"""
buses:
  - name: peer
    port: {master_device}
    protocol: modbus-rtu
    baudrate: 19200
    parity: N
    drives:
      - {{name: vfd, address: {UNIT}, control: bus, profile: peer-vfd.yaml,
          nominal_frequency_hz: 50, max_frequency_hz: 50, confirm_s: 5,
          monitor: [ir{CURRENT}]}}
""",
        encoding="utf-8",
    )
    (plan,) = load(config).lines
    clock = MonotonicClock()
    hub = Hub()
    fleet = FleetState((plan,), emit=hub.publish, clock=clock)
    transport = SerialTransport(plan.port, baudrate=plan.baudrate, parity=plan.parity)
    try:
        async with asyncio.timeout(60):
            await wait_for(lambda: server.transport is not None or serving.done())
            async with BusMaster(
                plan, codec=codec_for(plan), transport=transport, clock=clock, observer=fleet
            ) as master:
                yield Line(peer, master, fleet, hub)
    finally:
        await server.shutdown()  # type: ignore[no-untyped-call]  # pymodbus leaves it untyped
        serving.cancel()
        loop.remove_reader(m1)
        loop.remove_reader(m2)
        for fd in (m1, m2):
            os.close(fd)


async def test_every_value_read_matches_and_every_write_is_the_profiles_sequence(
    tmp_path: Path,
) -> None:
    async with peer_line(tmp_path) as line:
        await wait_for(lambda: line.master.planner.slot("vfd").online)
        await line.hub.wait_for(lambda: "ir300" in line.state()["values"], timeout_s=15)
        state = line.state()
        assert state["status_word"] == 0x0240
        assert state["running"] is False
        assert state["values"]["ir300"]["value"] == pytest.approx(12.3)
        assert state["values"]["ir300"]["name"] == "Motor current"
        # Adopted while stopped, the drive is fed its stop word, which leaves it as it is.
        assert set(line.peer.control_words()) <= {0x07}

        started = await orders(line.master, "vfd").start(frequency_hz=23.45)
        assert started.outcome is Outcome.DONE, started.reason
        await line.hub.wait_for(lambda: line.state()["output_frequency_hz"] == 23.45, timeout_s=15)
        assert line.state()["running"] is True
        assert (REFERENCE, 2345) in line.peer.writes
        words = line.peer.control_words()
        start = words.index(0x06)
        assert words[start : start + 3] == [0x06, 0x07, 0x0F]
        # Before the start, only the steady stop word; after it, only the steady run word.
        assert set(words[:start]) <= {0x07}
        await wait_for(lambda: len(line.peer.control_words()) > start + 4)
        assert set(line.peer.control_words()[start + 2 :]) == {0x0F}

        stopped = await orders(line.master, "vfd").stop()
        assert stopped.outcome is Outcome.DONE, stopped.reason
        assert line.peer.control_words()[-1] == 0x07
        await line.hub.wait_for(lambda: line.state()["running"] is False, timeout_s=15)
        every = set(line.peer.control_words())
        assert every <= {0x06, 0x07, 0x0F}
        assert {r for r, _ in line.peer.writes} <= {CONTROL, REFERENCE}
