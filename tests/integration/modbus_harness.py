"""A daemon (the real Service) over simulated lines whose frames the test can see.

Each line's transport is the simulator's, wrapped so that every frame the master writes is
kept: a test asserts on the control words and references that went on the wire, and on
the simulated drives themselves, never on what the code under test says it did.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

from fcmaster import config
from fcmaster.bus.plan import LinePlan
from fcmaster.clock import MonotonicClock
from fcmaster.protocol.danfoss_fc import decode_telegram
from fcmaster.protocol.framing import Framer
from fcmaster.service import Service
from fcmaster.sim.danfoss_fc.drive import FcSimDrive
from fcmaster.sim.line import SimLine
from fcmaster.sim.service import sim_line
from fcmaster.sim.transport import SimTransport
from fcmaster.transport.receiver import Handler, Piece
from tests.integration.ports import free_port

CONFIG = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    drives:
      - {name: pump-1, address: 1, control: bus, max_frequency_hz: 40,
         monitor: ["16-13", "16-14", "16-30", "16-90"]}
      - {name: fan-2, address: 2}
  - name: line2
    port: sim://line2
    baudrate: 115200
    drives:
      - {name: pump-3, address: 1, control: bus, modbus_unit: 11}
    simulation: SIMULATION
modbus: MODBUS
"""


class RecordingTransport:
    """The simulator's transport, keeping every frame written to the line."""

    def __init__(self, inner: SimTransport) -> None:
        self.inner = inner
        self.written: list[bytes] = []

    async def open(self) -> None:
        await self.inner.open()

    async def close(self) -> None:
        await self.inner.close()

    async def write(self, data: bytes) -> None:
        self.write_now(data)

    def write_now(self, data: bytes) -> None:
        self.written.append(data)
        self.inner.write_now(data)

    def watch_frame(self, framer: Framer, deadline: float, gap_s: float, handler: Handler) -> Piece:
        return self.inner.watch_frame(framer, deadline, gap_s, handler)

    def unwatch(self) -> None:
        self.inner.unwatch()

    def check_open(self) -> None:
        self.inner.check_open()

    async def read(self, deadline: float) -> bytes:
        return await self.inner.read(deadline)

    @property
    def received_at(self) -> float:
        return self.inner.received_at

    def discard_input(self) -> bytes:
        return self.inner.discard_input()

    @property
    def framing(self) -> RecordingTransport:
        return self

    adapter = None

    async def appeared(self) -> None:
        await asyncio.Event().wait()  # no device node


@dataclass
class Plant:
    """The running daemon, its simulated lines and what went on each wire."""

    service: Service
    port: int
    lines: dict[str, SimLine] = field(default_factory=dict)
    wires: dict[str, RecordingTransport] = field(default_factory=dict)

    def drive(self, bus: str, address: int) -> FcSimDrive:
        """A simulated FC drive."""
        for drive in self.lines[bus].drives:
            if drive.address == address:
                assert isinstance(drive, FcSimDrive)
                return drive
        raise KeyError(address)

    def online(self, bus: str, name: str) -> bool:
        """Whether the fleet shows drive ``name`` online."""
        state = self.service.fleet.get(bus, name)
        assert state is not None
        return state.online

    def control_sent(self, bus: str, address: int, since: int = 0) -> set[tuple[int, int]]:
        """The (control word, reference) pairs sent to ``address`` in frames ``since`` on."""
        sent = set()
        for frame in self.wires[bus].written[since:]:
            telegram = decode_telegram(frame, from_drive=False)
            if telegram.address == address:
                sent.add((telegram.pcd1, telegram.pcd2))
        return sent

    def frames(self, bus: str) -> int:
        """Frames written to ``bus`` so far."""
        return len(self.wires[bus].written)


@asynccontextmanager
async def plant(
    modbus: str = "{listen: 127.0.0.1:PORT, commands: true}",
    line2: str = "{}",
    clock: MonotonicClock | None = None,
) -> AsyncIterator[Plant]:
    """Run the daemon of :data:`CONFIG` with ``modbus`` as its section (PORT: a free one).

    ``line2`` is the second line's ``simulation`` section; ``clock`` the daemon's.
    """
    port = free_port()
    text = CONFIG.replace("MODBUS", modbus.replace("PORT", str(port)))
    parsed = config.parse(text.replace("SIMULATION", line2))
    clock = clock or MonotonicClock()
    lines: dict[str, SimLine] = {}
    wires: dict[str, RecordingTransport] = {}

    def transport(plan: LinePlan) -> RecordingTransport:
        bus = next(b for b in parsed.model.buses if b.name == plan.name)
        line = sim_line(plan, bus.simulation or {}, clock=clock)
        lines[plan.name] = line
        wires[plan.name] = RecordingTransport(SimTransport(line, clock, port=plan.port))
        return wires[plan.name]

    service = Service(parsed, clock=clock, transport_factory=transport)
    task = asyncio.create_task(service.run(install_signals=False), name="test.service")
    try:
        online = asyncio.create_task(
            service.hub.wait_for(
                lambda: all(s.online for s in service.fleet.snapshot()), timeout_s=10
            )
        )
        await asyncio.wait((online, task), return_when=asyncio.FIRST_COMPLETED)
        if task.done():  # the service ended (failed) before its drives came online
            online.cancel()
            task.result()
        else:
            online.result()
        yield Plant(service, port, lines, wires)
    finally:
        service.stop()
        async with asyncio.timeout(10):
            await task
