"""Command → wire latency through a real MQTT broker.

Run: ``python benchmarks/mqtt_latency.py [--count 200] [--drives 4] [--baudrate 115200]``
(needs mosquitto; it starts its own on a free loopback port).

A daemon (:class:`fcmaster.service.Service`) polls simulated FC drives on an in-process
``sim://`` line in real time; the MQTT bridge connects to the broker; a plant client in the
same process publishes commands (QoS 1) and waits for each result before the next, at a
random phase of the poll cycle. Timestamps, all from one ``perf_counter``:

* ``t0`` the client publishes the command;
* ``t1`` the bridge hands it to the gateway (``execute`` is called);
* ``t2`` the telegram carrying it is written to the line (the transport's ``write``);
* ``t3`` the client has the result.

``t1 - t0`` is the broker and the bridge; ``t2 - t1`` the bus master's scheduling (at most
the transaction in flight, since commands go before the idle poll); ``t2 - t0`` is the
figure asked for, command → wire. Two kinds: ``read`` of 3-41 (not in the poll rotation,
so its telegram is unmistakable) and alternating ``start``/``stop`` (the first telegram
whose control word differs). The event loop is fcmaster's precise one, as in the daemon.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import random
import shutil
import signal
import socket
import statistics
import tempfile
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import aiomqtt

from fcmaster.adapters.gateway import LineInfo
from fcmaster.adapters.mqtt import MqttAdapter
from fcmaster.adapters.settings import MqttSettings
from fcmaster.bus.commands import Command, CommandResult
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import Clock, new_event_loop
from fcmaster.config import parse
from fcmaster.hub import Hub
from fcmaster.protocol.danfoss_fc import decode_telegram
from fcmaster.protocol.framing import Framer
from fcmaster.service import Service
from fcmaster.sim.service import sim_transport
from fcmaster.state import FleetState
from fcmaster.transport.pipe import Framing, Transport
from fcmaster.transport.receiver import Handler, Piece
from fcmaster.transport.usb import Adapter

now = time.perf_counter
NODELAY = ((socket.IPPROTO_TCP, socket.TCP_NODELAY, 1),)


class TapTransport:
    """A transport that notes when each request goes on the wire."""

    def __init__(self, inner: Transport) -> None:
        self.inner = inner
        self.writes: list[tuple[float, bytes]] = []

    async def open(self) -> None:
        await self.inner.open()

    async def close(self) -> None:
        await self.inner.close()

    async def write(self, data: bytes) -> None:
        self.write_now(data)

    def write_now(self, data: bytes) -> None:
        self.writes.append((now(), data))
        self._framing().write_now(data)

    async def read(self, deadline: float) -> bytes:
        return await self.inner.read(deadline)

    def watch_frame(self, framer: Framer, deadline: float, gap_s: float, handler: Handler) -> Piece:
        return self._framing().watch_frame(framer, deadline, gap_s, handler)

    def unwatch(self) -> None:
        self._framing().unwatch()

    def check_open(self) -> None:
        self._framing().check_open()

    def _framing(self) -> Framing:
        framing = self.inner.framing
        assert framing is not None
        return framing

    @property
    def framing(self) -> TapTransport:
        return self

    @property
    def adapter(self) -> Adapter | None:
        return self.inner.adapter

    async def appeared(self) -> None:
        await self.inner.appeared()

    @property
    def received_at(self) -> float:
        return self.inner.received_at

    def discard_input(self) -> bytes:
        return self.inner.discard_input()


class TapGateway:
    """The service as the bridge sees it, noting when each command reaches ``execute``."""

    def __init__(self, service: Service) -> None:
        self.service = service
        self.calls: list[float] = []

    @property
    def clock(self) -> Clock:
        return self.service.clock

    @property
    def hub(self) -> Hub:
        return self.service.hub

    @property
    def fleet(self) -> FleetState:
        return self.service.fleet

    def drive_plan(self, name: str) -> DrivePlan | None:
        return self.service.drive_plan(name)

    def lines(self) -> list[LineInfo]:
        return self.service.lines()

    async def execute(self, drive: str, command: Command) -> CommandResult:
        self.calls.append(now())
        return await self.service.execute(drive, command)


@contextlib.asynccontextmanager
async def mosquitto(directory: Path, *, nodelay: bool) -> AsyncIterator[int]:
    binary = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    config = directory / "mosquitto.conf"
    config.write_text(
        f"listener {port} 127.0.0.1\nallow_anonymous true\nset_tcp_nodelay {str(nodelay).lower()}\n"
    )
    process = await asyncio.create_subprocess_exec(
        binary, "-c", str(config), stderr=asyncio.subprocess.DEVNULL
    )
    try:
        for _ in range(200):
            try:
                _, writer = await asyncio.open_connection("127.0.0.1", port)
            except OSError:
                await asyncio.sleep(0.02)
                continue
            writer.close()
            break
        yield port
    finally:
        process.send_signal(signal.SIGKILL)
        await process.wait()


def config_text(drives: int, baudrate: int) -> str:
    lines = "\n".join(
        f"      - {{name: d{n}, address: {n}{', control: bus' if n == 1 else ''}}}"
        for n in range(1, drives + 1)
    )
    bus = f"  - name: line1\n    port: sim://line1\n    baudrate: {baudrate}\n"
    return f"buses:\n{bus}    drives:\n{lines}\n"


def wire_time(tap: TapTransport, after: float, kind: str, last_pcd1: int | None) -> float:
    for at, frame in tap.writes:
        if at < after:
            continue
        telegram = decode_telegram(frame, from_drive=False)
        if telegram.address != 1:
            continue
        if kind == "read" and telegram.pke is not None and telegram.pke & 0x7FF == 341:
            return at
        if kind == "control" and last_pcd1 is not None and telegram.pcd1 != last_pcd1:
            return at
    raise RuntimeError(f"no {kind} telegram on the wire after {after}")


def last_control_word(tap: TapTransport) -> int | None:
    for _, frame in reversed(tap.writes):
        telegram = decode_telegram(frame, from_drive=False)
        if telegram.address == 1:
            return telegram.pcd1
    return None


def summary(name: str, samples: list[float]) -> str:
    ms = sorted(s * 1000 for s in samples)
    q = statistics.quantiles(ms, n=100)
    return f"{name:<34} p50 {q[49]:6.2f}  p90 {q[89]:6.2f}  p99 {q[98]:6.2f}  max {ms[-1]:6.2f} ms"


async def measure(count: int, drives: int, baudrate: int, *, nodelay: bool) -> None:
    taps: list[TapTransport] = []
    config = parse(config_text(drives, baudrate))

    def factory(plan: LinePlan) -> Transport:
        tap = TapTransport(sim_transport(plan, {}, clock=service.clock))
        taps.append(tap)
        return tap

    service = Service(config, transport_factory=factory)
    with tempfile.TemporaryDirectory() as directory:
        async with mosquitto(Path(directory), nodelay=nodelay) as port:
            running = asyncio.create_task(service.run(install_signals=False))
            gateway = TapGateway(service)
            adapter = MqttAdapter(
                MqttSettings(url=f"mqtt://127.0.0.1:{port}", commands=True, trust_broker=True),
                gateway,
            )
            async with adapter, aiomqtt.Client("127.0.0.1", port, socket_options=NODELAY) as client:
                await adapter.connected.wait()
                await client.subscribe("fcmaster/line1/d1/command/result", qos=1)
                await service.hub.wait_for(lambda: all(s.online for s in service.fleet.snapshot()))
                tap = taps[0]
                rows: dict[str, list[list[float]]] = {"read": [], "control": []}
                messages = client.messages
                for n in range(count):
                    for kind in ("read", "control"):
                        await asyncio.sleep(random.uniform(0.0, 0.02))  # a random poll phase
                        if kind == "read":
                            body: dict[str, Any] = {"action": "read", "parameter": "3-41"}
                        else:
                            body = {"action": "start" if n % 2 == 0 else "stop"}
                        pcd1 = last_control_word(tap)
                        calls = len(gateway.calls)
                        t0 = now()
                        await client.publish(
                            "fcmaster/line1/d1/command",
                            json.dumps({"id": n, **body}),
                            qos=1,
                        )
                        reply = await anext(messages)
                        result = json.loads(reply.payload)  # type: ignore[arg-type]
                        t3 = now()
                        if result["id"] != n or result["outcome"] != "done":
                            raise RuntimeError(f"unexpected result {result}")
                        t1 = gateway.calls[calls]
                        t2 = wire_time(tap, t1, kind, pcd1)
                        rows[kind].append([t1 - t0, t2 - t1, t2 - t0, t3 - t0])
            service.stop()
            await running
    plan = config.lines[0]
    print(
        f"{count} commands of each kind, {drives} drives on one sim line at {baudrate} baud "
        f"({plan.char_bits} bits/char, 10 ms response delay), mosquitto on loopback "
        f"with set_tcp_nodelay {str(nodelay).lower()}"
    )
    for kind, samples in rows.items():
        print(f"-- {kind}")
        for index, name in enumerate(
            [
                "publish → execute (broker, bridge)",
                "execute → wire (bus scheduling)",
                "publish → wire",
                "publish → result at the client",
            ]
        ):
            print(summary(name, [row[index] for row in samples]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=200)
    parser.add_argument("--drives", type=int, default=4)
    parser.add_argument("--baudrate", type=int, default=115200)
    args = parser.parse_args()
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        for nodelay in (True, False):
            runner.run(measure(args.count, args.drives, args.baudrate, nodelay=nodelay))


if __name__ == "__main__":
    main()
