"""fcmaster against pymodbus's own client, polling the same pymodbus RTU server on a pty.

Run: ``python benchmarks/modbus_rtu_peer.py [--duration S] [--output PATH]``.

The server (pymodbus's ``ModbusSerialServer``, a register map with a status word and an
output frequency side by side) runs in a process of its own on one end of a pair of
pseudo-terminals joined back to back; each master polls it from the other end in turn:

* **fcmaster**: the real :class:`~fcmaster.bus.master.BusMaster` on the real
  :class:`~fcmaster.transport.serial.SerialTransport`, one monitor-only drive whose profile (a
  user profile file's, read as the config reads it) puts status and frequency in one read;
* **pymodbus**: ``AsyncModbusSerialClient.read_holding_registers`` of the same two
  registers, one after the other, as fast as it goes.

A pty has no baud rate: no wire time is simulated, so these are the masters' and the
server's software costs alone. Figures per transaction: CPU seconds of the master's own
process (``time.process_time``), and wall time. The server's CPU is the same for both.

Benchmarks are not tests: nothing here passes or fails.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import subprocess
import sys
import time
import tty
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Final

import results_file
from pymodbus import FramerType
from pymodbus.client import AsyncModbusSerialClient
from pymodbus.server import ModbusSerialServer
from pymodbus.simulator import DataType, SimData, SimDevice

from fcmaster import logsetup
from fcmaster.bus.codecs import codec_for
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock, new_event_loop
from fcmaster.protocol.modbus_rtu.profile_file import parse_profile_text
from fcmaster.transport.serial import SerialTransport

UNIT: Final = 7
STATUS: Final = 200  # status word, then output frequency
WARMUP_S: Final = 0.5
DEFAULT_OUTPUT: Final = Path(__file__).resolve().parent / "results" / "modbus_rtu_peer.json"
PROFILE: Final = f"""
name: peer-vfd
registers:
  control: {{address: 100}}
  reference: {{address: 101, scale: 0.01, unit: Hz}}
  status: {{address: {STATUS}}}
  output_frequency: {{address: {STATUS + 1}, scale: 0.01, unit: Hz}}
commands: {{start: [1], stop: [0]}}
status_bits: {{running: 2, fault: 3}}
"""


async def _serve() -> None:
    """The server on one end of a pty pair; the other end's path on stdout."""
    m1, s1 = os.openpty()
    m2, s2 = os.openpty()
    for fd in (s1, s2):
        tty.setraw(fd)
    loop = asyncio.get_running_loop()

    def forward(src: int, dst: int) -> None:
        with contextlib.suppress(OSError):
            os.write(dst, os.read(src, 4096))

    loop.add_reader(m1, forward, m1, m2)
    loop.add_reader(m2, forward, m2, m1)
    registers = [
        SimData(address=100, values=[0, 0], datatype=DataType.REGISTERS),
        SimData(address=STATUS, values=[0x0627, 2345], datatype=DataType.REGISTERS),
    ]
    server = ModbusSerialServer(
        SimDevice(id=UNIT, simdata=registers), port=os.ttyname(s1), framer=FramerType.RTU
    )
    serving = asyncio.create_task(server.serve_forever())
    print(os.ttyname(s2), flush=True)
    while await loop.run_in_executor(None, sys.stdin.readline):
        pass
    await server.shutdown()  # type: ignore[no-untyped-call]
    serving.cancel()


@contextlib.contextmanager
def server() -> Iterator[str]:
    """A server process for the block; the master's pty path."""
    process = subprocess.Popen(
        [sys.executable, os.path.abspath(__file__), "--serve"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert process.stdin is not None
    assert process.stdout is not None
    try:
        yield process.stdout.readline().strip()
    finally:
        process.stdin.close()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def _figures(master: str, transactions: int, cpu_s: float, wall_s: float) -> dict[str, Any]:
    return {
        "master": master,
        "transactions": transactions,
        "transactions_per_s": round(transactions / wall_s, 1),
        "cpu_us_per_transaction": round(cpu_s / transactions * 1e6, 1),
        "wall_ms_per_transaction": round(wall_s / transactions * 1000, 3),
        "load_average": os.getloadavg()[0],
    }


async def fcmaster_case(path: str, duration_s: float) -> dict[str, Any]:
    """The BusMaster polling the one drive for ``duration_s``."""
    profile = parse_profile_text(PROFILE)
    plan = LinePlan(
        name="peer", port=path, protocol="modbus-rtu", parity="N", response_delay_s=0.0,
        drives=(DrivePlan(name="vfd", address=UNIT, profile=profile, monitor=()),),
    )  # fmt: skip
    transport = SerialTransport(path, baudrate=plan.baudrate, parity=plan.parity)
    clock = MonotonicClock()
    async with BusMaster(plan, codec=codec_for(plan), transport=transport, clock=clock) as master:
        await asyncio.sleep(WARMUP_S)
        replies, cpu, wall = master.stats.replies, time.process_time(), time.perf_counter()
        await asyncio.sleep(duration_s)
        replies = master.stats.replies - replies
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    return _figures("fcmaster", replies, cpu, wall)


async def pymodbus_case(path: str, duration_s: float) -> dict[str, Any]:
    """pymodbus's client reading the same registers back to back for ``duration_s``."""
    client = AsyncModbusSerialClient(path, framer=FramerType.RTU, parity="N", timeout=1)
    await client.connect()
    try:
        end = time.perf_counter() + WARMUP_S
        while time.perf_counter() < end:
            await client.read_holding_registers(STATUS, count=2, device_id=UNIT)
        count, cpu, wall = 0, time.process_time(), time.perf_counter()
        end = wall + duration_s
        while time.perf_counter() < end:
            answer = await client.read_holding_registers(STATUS, count=2, device_id=UNIT)
            count += not answer.isError()
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    finally:
        client.close()
    return _figures("pymodbus", count, cpu, wall)


def main(argv: list[str] | None = None) -> int:
    """Run both masters in turn; print a table; write the JSON results."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--duration", type=float, default=10.0, help="seconds per master")
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    parser.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve:
        asyncio.run(_serve())
        return 0
    logsetup.configure(level="warning", fmt="json")
    rows = []
    for case in (fcmaster_case, pymodbus_case):
        with server() as path, asyncio.Runner(loop_factory=new_event_loop) as runner:
            row = runner.run(case(path, args.duration))
        rows.append(row)
        print(
            f"{row['master']:<9} {row['transactions_per_s']:>8.1f}/s  "
            f"CPU {row['cpu_us_per_transaction']:>7.1f} µs/transaction  "
            f"wall {row['wall_ms_per_transaction']:.3f} ms  load {row['load_average']:.2f}",
            flush=True,
        )
    args.output.parent.mkdir(parents=True, exist_ok=True)
    results_file.write(args.output, {**results_file.provenance("modbus_rtu_peer"), "cases": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
