"""A broker outage under a steady stream of changes: what the Sparkplug edge node delivers after.

Run: ``python benchmarks/sparkplug_outage.py [--rate 1000] [--outage-s 60] [--drives 10]
[--output PATH]`` (needs mosquitto; it starts its own on a free loopback port).

In one process: a fleet state and hub (the daemon's own) with ``--drives`` drives, fed
``--rate`` changes per second — each one a new output frequency of one drive, round robin, so
every change is one DDATA metric and carries its own number (the frequency in tenths of a Hz
is the drive's count of changes) — the :class:`SparkplugAdapter` with a store on disk, and a
host application that decodes every DDATA. Phases: ``--warmup-s`` live; the broker killed
(SIGKILL) for ``--outage-s`` while the changes go on; the broker back, the host reconnected,
and the changes still going on while the store drains, until every change made is accounted
for or ``--drain-limit-s`` passes.

Figures: of the changes made from the moment of the kill to the broker's return (and those in
the socket when it died), the share that arrived afterwards (live or historical), whether each
drive's history arrived in the order made, duplicates; the latency of live data (change made →
decoded by the host) before the outage and during the drain (p50, p99, max); how long the
drain took; the store's size on disk at its largest. The host decodes in the same process, so
its work is in the latency too.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import getpass
import shutil
import signal
import socket
import statistics
import sys
import tempfile
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import aiomqtt
import results_file

from fcmaster.adapters.settings import SparkplugSettings
from fcmaster.adapters.sparkplug.adapter import SparkplugAdapter
from fcmaster.adapters.sparkplug.payload import decode_payload
from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock
from fcmaster.hub import Hub
from fcmaster.protocol.codec import DriveStatus, Reply
from fcmaster.state import FleetState

now = time.perf_counter
GROUP, NODE = "Plant", "bench"


class Gateway:
    """The daemon as the adapter sees it: a real hub and fleet state, commands refused."""

    def __init__(self, drives: int) -> None:
        self.plans = tuple(DrivePlan(name=f"d{n}", address=n) for n in range(1, drives + 1))
        self.line = LinePlan(name="line1", port="sim://line1", drives=self.plans)
        self.clock = MonotonicClock()
        self.hub = Hub()
        self.fleet = FleetState((self.line,), emit=self.hub.publish, clock=self.clock)

    def drive_plan(self, name: str) -> DrivePlan | None:
        return next((p for p in self.plans if p.name == name), None)

    async def execute(self, drive: str, command: Command) -> CommandResult:
        return CommandResult(outcome=Outcome.NOT_ALLOWED, reason="a benchmark")

    def reply(self, plan: DrivePlan, hz: float) -> None:
        status = DriveStatus(
            word=0x0E07, running=True, fault=False, warning=False, at_reference=True
        )
        reply = Reply(address=plan.address, status=status, output_frequency_hz=hz)
        self.fleet.drive_replied("line1", plan, reply, self.clock.now(), None)


class Mosquitto:
    """A broker on a fixed loopback port that can be killed and started again."""

    def __init__(self, directory: Path) -> None:
        with socket.socket() as sock:
            sock.bind(("127.0.0.1", 0))
            self.port = sock.getsockname()[1]
        self.config = directory / "mosquitto.conf"
        user = getpass.getuser()  # as root, mosquitto would become "mosquitto"
        self.config.write_text(
            f"listener {self.port} 127.0.0.1\nallow_anonymous true\nuser {user}\n"
        )
        self.process: asyncio.subprocess.Process | None = None

    async def start(self) -> None:
        binary = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
        self.process = await asyncio.create_subprocess_exec(
            binary, "-c", str(self.config), stderr=asyncio.subprocess.DEVNULL
        )
        for _ in range(500):
            try:
                _, writer = await asyncio.open_connection("127.0.0.1", self.port)
            except OSError:
                await asyncio.sleep(0.02)
                continue
            writer.close()
            return
        raise RuntimeError("mosquitto did not start")

    async def kill(self) -> None:
        if self.process is not None:
            self.process.send_signal(signal.SIGKILL)
            await self.process.wait()
            self.process = None


class Host:
    """Decodes every DDATA: each change's number, when it arrived, historical or not."""

    def __init__(self, drives: int) -> None:
        self.drives = drives
        self.live: dict[int, float] = {}  # change number → arrival
        self.history: list[tuple[int, int]] = []  # (drive index, change number) in arrival order
        self.seen: dict[int, int] = {}  # change number → times received

    async def run(self, port: int, ready: asyncio.Event) -> None:
        async with aiomqtt.Client("127.0.0.1", port) as client:
            await client.subscribe(f"spBv1.0/{GROUP}/DDATA/#", qos=0)
            ready.set()
            async for message in client.messages:
                arrived = now()
                device = message.topic.value.rsplit("/", 1)[-1]
                index = int(device[1:]) - 1
                assert isinstance(message.payload, bytes | bytearray)
                for metric in decode_payload(bytes(message.payload)).metrics:
                    if metric.name != "Output Frequency" or not isinstance(metric.value, float):
                        continue
                    number = round(metric.value * 10) * self.drives + index
                    self.seen[number] = self.seen.get(number, 0) + 1
                    if metric.is_historical:
                        self.history.append((index, number))
                    else:
                        self.live.setdefault(number, arrived)


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _percentiles(samples: list[float]) -> dict[str, float | None]:
    if not samples:
        return {"count": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
    ordered = sorted(samples)
    return {
        "count": len(ordered),
        "p50_ms": statistics.median(ordered) * 1000,
        "p99_ms": ordered[min(len(ordered) - 1, int(len(ordered) * 0.99))] * 1000,
        "max_ms": ordered[-1] * 1000,
    }


@contextlib.asynccontextmanager
async def hosted(host: Host, port: int) -> AsyncIterator[None]:
    ready = asyncio.Event()
    task = asyncio.create_task(host.run(port, ready))
    await asyncio.wait([task, asyncio.create_task(ready.wait())], return_when="FIRST_COMPLETED")
    try:
        yield
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError, aiomqtt.MqttError):
            await task


async def figures(args: argparse.Namespace) -> dict[str, Any]:
    gateway = Gateway(args.drives)
    host = Host(args.drives)
    with tempfile.TemporaryDirectory() as directory:
        broker = Mosquitto(Path(directory))
        await broker.start()
        try:
            return await _outage(args, gateway, host, broker, Path(directory))
        finally:
            await broker.kill()


async def _outage(
    args: argparse.Namespace, gateway: Gateway, host: Host, broker: Mosquitto, directory: Path
) -> dict[str, Any]:
    made: dict[int, float] = {}  # change number → when made
    counts = [0] * args.drives
    phase = {"name": "warmup"}
    phases: dict[str, list[int]] = {"warmup": [], "outage": [], "drain": []}

    async def produce() -> None:
        period = 1.0 / args.rate
        due = now()
        k = 0
        while True:
            index = k % args.drives
            counts[index] += 1
            number = counts[index] * args.drives + index
            made[number] = now()
            phases[phase["name"]].append(number)
            gateway.reply(gateway.plans[index], counts[index] / 10)
            k += 1
            due += period
            delay = due - now()
            if delay > 0:
                await asyncio.sleep(delay)
            elif k % 100 == 0:
                await asyncio.sleep(0)

    store = directory / "spool" / "sparkplug.db"
    settings = SparkplugSettings(
        url=f"mqtt://127.0.0.1:{broker.port}",
        group_id=GROUP,
        edge_node_id=NODE,
        store=str(store),
        reconnect_min_s=0.2,
        reconnect_max_s=1.0,
    )
    for plan in gateway.plans:  # online from the start: born at the first connection
        gateway.reply(plan, 0.0)
    node_gateway: Any = gateway  # the parts of the Gateway protocol the adapter uses
    async with SparkplugAdapter(settings, node_gateway) as node, hosted(host, broker.port):
        await node.connected.wait()
        producer = asyncio.create_task(produce())
        await asyncio.sleep(args.warmup_s)
        _say(f"outage of {args.outage_s} s")
        phase["name"] = "outage"
        outage_at = now()
        await broker.kill()
        largest = 0
        while now() - outage_at < args.outage_s:
            await asyncio.sleep(1.0)
            largest = max(largest, await node.forward.size_bytes())
        await broker.start()
        _say("broker back: draining")
        phase["name"] = "drain"
        drain_at = now()
        async with hosted(host, broker.port):
            outage = set(phases["outage"])
            replayed, last_missing, stalled = -1, -1, 0
            while now() - drain_at < args.drain_limit_s:
                await asyncio.sleep(1.0)
                largest = max(largest, await node.forward.size_bytes())
                missing = len(outage - host.seen.keys())
                _say(f"missing {missing}, replayed {node.forward.replayed}")
                if not missing:
                    break
                if node.forward.replayed == replayed and missing == last_missing:
                    stalled += 1
                    if stalled >= 10:  # ten seconds without progress: it will not come
                        break
                else:
                    stalled = 0
                replayed, last_missing = node.forward.replayed, missing
            drained_s = now() - drain_at
            producer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await producer
            await asyncio.sleep(1.0)
        replayed, unborn = node.forward.replayed, node.forward.unborn
        recorded, dropped = node.forward.last_n, node.forward.writer.dropped
    file_bytes = sum(p.stat().st_size for p in store.parent.glob("sparkplug.db*"))

    delivered = [n for n in phases["outage"] if n in host.seen]
    in_order = all(
        a < b
        for index in range(args.drives)
        for a, b in zip(
            [n for i, n in host.history if i == index],
            [n for i, n in host.history if i == index][1:],
            strict=False,
        )
    )

    def latencies(numbers: list[int]) -> list[float]:
        return [host.live[n] - made[n] for n in numbers if n in host.live]

    return {
        **results_file.provenance("sparkplug_outage"),
        "load_average": list(__import__("os").getloadavg()),
        "settings": {
            "rate_per_s": args.rate,
            "outage_s": args.outage_s,
            "drives": args.drives,
            "warmup_s": args.warmup_s,
        },
        "changes_made": {name: len(numbers) for name, numbers in phases.items()},
        "outage_changes_delivered_pct": 100.0 * len(delivered) / max(1, len(phases["outage"])),
        "outage_changes_missing": len(phases["outage"]) - len(delivered),
        "missing_sample": [n for n in phases["outage"] if n not in host.seen][:20],
        "history_in_order_per_drive": in_order,
        "history_received": len(host.history),
        "duplicates": sum(c - 1 for c in host.seen.values() if c > 1),
        "changes_taken_in": recorded,  # the rest were conflated by the hub before it read them
        "store_dropped": dropped,
        "replayed_rows": replayed,
        "unborn_rows": unborn,
        "drain_s": drained_s,
        "live_latency_warmup": _percentiles(latencies(phases["warmup"])),
        "live_latency_during_drain": _percentiles(latencies(phases["drain"])),
        "store_used_bytes_max": largest,
        "store_file_bytes_after": file_bytes,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=1000.0, help="changes per second")
    parser.add_argument("--outage-s", type=float, default=60.0)
    parser.add_argument("--warmup-s", type=float, default=5.0)
    parser.add_argument("--drain-limit-s", type=float, default=600.0)
    parser.add_argument("--drives", type=int, default=10)
    parser.add_argument(
        "--output",
        type=Path,
        default=Path(__file__).parent / "results" / "sparkplug_outage.json",
    )
    args = parser.parse_args()
    results_file.run_and_write(figures(args), args.output)


if __name__ == "__main__":
    main()
