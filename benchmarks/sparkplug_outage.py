"""A broker outage under a steady stream of changes: what the Sparkplug edge node delivers after.

Run: ``python benchmarks/sparkplug_outage.py [--rate 1000] [--outage-s 60] [--drives 10]
[--host-in-process] [--output PATH]`` (needs mosquitto; it starts its own on a free loopback
port).

In one process: a fleet state and hub (the daemon's own) with ``--drives`` drives, fed
``--rate`` changes per second — each one a new output frequency of one drive, round robin, so
every change is one DDATA metric and carries its own number (the frequency in tenths of a Hz
is the drive's count of changes) — and the :class:`SparkplugAdapter` with a store on disk.
In a process of its own (as a SCADA host is; ``--host-in-process``: in the node's, its
decoding then counted in the node's latency), the primary host application: it publishes its
STATE online at each connection (the node is born only then) and decodes every DDATA. Both
stamp with ``time.monotonic()``, the same clock in every process of the machine. Phases:
``--warmup-s`` live; the broker killed (SIGKILL) for ``--outage-s`` while the changes go on;
the broker back, the host reconnected, and the changes still going on while the store
drains, until every change made is accounted for or ``--drain-limit-s`` passes.

Figures: of the changes made from the moment of the kill to the broker's return (and those in
the socket when it died), the share that arrived afterwards (live or historical), whether each
drive's history arrived in the order made, duplicates; the latency of live data (change made →
decoded by the host) before the outage and during the drain (p50, p99, max); how long the
drain took; the store's size on disk at its largest; and a timeline every ``--sample-s``: the
CPU used by the node's process, the host's and the broker's, how late the node's loop woke
(max), what waited in the node (its queue of live messages, publications in the MQTT client
not yet written, snapshots the hub held for it, rows for the store's writer), history
replayed so far, and the live latency of the changes that arrived in that window (p99, max).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import getpass
import itertools
import json
import os
import random
import resource
import shutil
import signal
import socket
import statistics
import sys
import tempfile
import time
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

now = time.monotonic  # the same clock in every process of the machine
GROUP, NODE, HOST_ID = "Plant", "bench", "bench-host"
TICK_S = 0.005  # the loop-lateness probe's period


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


def broker_port() -> int:
    """A free loopback port below the ephemeral range.

    Not one the kernel hands out: a client that keeps reconnecting to a port of that range
    while nothing listens on it is, now and then, given that very port as its own and
    connects to itself (TCP's simultaneous open), and then holds it: the broker cannot
    listen there again (seen once in a 10-minute outage).
    """
    low = int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    for port in random.sample(range(max(1024, low - 12000), low), 200):
        with socket.socket() as sock:
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    raise RuntimeError("no free port below the ephemeral range")


def mosquitto_config(directory: Path) -> tuple[int, Path]:
    """A free loopback port and a mosquitto config in ``directory`` that listens on it."""
    port = broker_port()
    config = directory / "mosquitto.conf"
    user = getpass.getuser()  # as root, mosquitto would become "mosquitto"
    config.write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\nuser {user}\n")
    return port, config


MOSQUITTO = shutil.which("mosquitto") or "/usr/sbin/mosquitto"


class Mosquitto:
    """A broker on a fixed loopback port that can be killed and started again."""

    def __init__(self, directory: Path) -> None:
        self.port, self.config = mosquitto_config(directory)
        self.process: asyncio.subprocess.Process | None = None

    async def start(self) -> None:
        self.process = await asyncio.create_subprocess_exec(
            MOSQUITTO, "-c", str(self.config), stderr=asyncio.subprocess.DEVNULL
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


def _state(online: bool) -> bytes:
    return json.dumps({"online": online, "timestamp": time.time_ns() // 1_000_000}).encode()


class Host:
    """The primary host: its STATE online at each connection; decodes every DDATA.

    Keeps each change's number, when it arrived, historical or not. Reconnects by itself.
    """

    def __init__(self, drives: int, port: int) -> None:
        self.drives = drives
        self.port = port
        self.live: dict[int, float] = {}  # change number → arrival
        self.history: list[tuple[int, int]] = []  # (drive index, change number) in arrival order
        self.seen: dict[int, int] = {}  # change number → times received
        self.subscribed = asyncio.Event()

    async def run(self) -> None:
        topic = f"spBv1.0/STATE/{HOST_ID}"
        while True:
            will = aiomqtt.Will(topic, _state(False), qos=1, retain=True)
            try:
                async with aiomqtt.Client("127.0.0.1", self.port, will=will) as client:
                    await client.subscribe(f"spBv1.0/{GROUP}/DDATA/#", qos=0)
                    await client.publish(topic, _state(True), qos=1, retain=True)
                    self.subscribed.set()
                    async for message in client.messages:
                        assert isinstance(message.payload, bytes | bytearray)
                        self.take(message.topic.value, bytes(message.payload), now())
            except aiomqtt.MqttError:
                self.subscribed.clear()
                await asyncio.sleep(0.05)

    def take(self, topic: str, payload: bytes, arrived: float) -> None:
        index = int(topic.rsplit("/", 1)[-1][1:]) - 1
        for metric in decode_payload(payload).metrics:
            if metric.name != "Output Frequency" or not isinstance(metric.value, float):
                continue
            number = round(metric.value * 10) * self.drives + index
            self.seen[number] = self.seen.get(number, 0) + 1
            if metric.is_historical:
                self.history.append((index, number))
            else:
                self.live.setdefault(number, arrived)

    def results(self) -> dict[str, Any]:
        return {
            "live": list(self.live.items()),
            "history": self.history,
            "seen": list(self.seen.items()),
        }


class HostHere:
    """The host in the node's own process."""

    def __init__(self, drives: int, port: int) -> None:
        self.host = Host(drives, port)
        self._task: asyncio.Task[None] | None = None

    async def start(self) -> None:
        self._task = asyncio.create_task(self.host.run())
        await self.host.subscribed.wait()

    async def missing(self, numbers: list[int]) -> int:
        return sum(1 for n in numbers if n not in self.host.seen)

    async def finish(self) -> dict[str, Any]:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        return self.host.results()

    def cpu_s(self) -> float | None:
        return None  # counted in the node's process


class HostProcess:
    """The host in a process of its own (``--serve-host``), asked over its stdin and stdout."""

    def __init__(self, drives: int, port: int, directory: Path) -> None:
        self.args = ["--serve-host", str(port), "--drives", str(drives)]
        self.directory = directory
        self.process: asyncio.subprocess.Process | None = None
        self._watching = False

    async def start(self) -> None:
        self.process = await asyncio.create_subprocess_exec(
            sys.executable, __file__, *self.args,
            stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
        )  # fmt: skip
        await self._ask("ready")

    async def _ask(self, line: str) -> str:
        process = self.process
        assert process is not None
        assert process.stdin is not None
        assert process.stdout is not None
        process.stdin.write(f"{line}\n".encode())
        await process.stdin.drain()
        return (await process.stdout.readline()).decode().strip()

    async def missing(self, numbers: list[int]) -> int:
        if not self._watching:  # the numbers to look for, once (off the loop: a big file)
            file = self.directory / "watch.json"
            await asyncio.to_thread(lambda: file.write_text(json.dumps(numbers)))
            self._watching = True
        return int(await self._ask(f"missing {self.directory / 'watch.json'}"))

    async def finish(self) -> dict[str, Any]:
        out = self.directory / "host.json"
        await self._ask(f"dump {out}")
        assert self.process is not None
        await self.process.wait()
        found: dict[str, Any] = json.loads(out.read_text())
        return found

    def cpu_s(self) -> float | None:
        return None if self.process is None else _cpu_s(self.process.pid)


async def serve_host(port: int, drives: int) -> None:
    """``--serve-host``: the host, answering ``ready``, ``missing FILE`` and ``dump FILE``."""
    host = Host(drives, port)
    task = asyncio.create_task(host.run())
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    watched: list[int] = []
    while line := (await reader.readline()).decode().split():
        if line[0] == "ready":
            await host.subscribed.wait()
            answer = "ready"
        elif line[0] == "missing":
            watched = watched or json.loads(await asyncio.to_thread(Path(line[1]).read_text))
            answer = str(sum(1 for n in watched if n not in host.seen))
        else:
            task.cancel()
            await asyncio.to_thread(Path(line[1]).write_text, json.dumps(host.results()))
            answer = "dumped"
        print(answer, flush=True)
        if line[0] == "dump":
            return


def _cpu_s(pid: int) -> float | None:
    """CPU seconds used so far by process ``pid`` (None: it is gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _own_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


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


class Timeline:
    """Every ``period_s``: CPU of each process, the loop's lateness, what waits in the node."""

    def __init__(self, period_s: float, node: Any, host: HostHere | HostProcess) -> None:
        self.period_s = period_s
        self.node = node
        self.host = host
        self.broker_pid: int | None = None
        self.phase = "warmup"
        self.samples: list[dict[str, Any]] = []
        self.started = now()
        self._late_max = 0.0

    async def probe(self) -> None:
        """How late the loop wakes from a short sleep: the most in each window."""
        while True:
            due = now() + TICK_S
            await asyncio.sleep(TICK_S)
            self._late_max = max(self._late_max, now() - due)

    async def run(self) -> None:
        probe = asyncio.create_task(self.probe())
        try:
            await self._sample()
        finally:
            probe.cancel()

    async def _sample(self) -> None:
        last = (now(), _own_cpu_s(), self.host.cpu_s(), self._broker_cpu())
        while True:
            await asyncio.sleep(self.period_s)
            at, own, host, broker = now(), _own_cpu_s(), self.host.cpu_s(), self._broker_cpu()
            wall = at - last[0]
            node = self.node
            client = node._client
            subscription = node._subscription
            self.samples.append(
                {
                    "t_s": round(at - self.started, 1),
                    "phase": self.phase,
                    "cpu_node_pct": round(100 * (own - last[1]) / wall),
                    "cpu_host_pct": _share(host, last[2], wall),
                    "cpu_broker_pct": _share(broker, last[3], wall),
                    "loop_late_max_ms": round(self._late_max * 1000, 1),
                    "queued": len(node._queue),
                    "in_mqtt_client": len(client._client._out_packet) if client else None,
                    "hub_behind": subscription.pending if subscription else None,
                    "store_pending": node.forward.writer._queue.qsize(),
                    "replayed": node.forward.replayed,
                }
            )
            self._late_max = 0.0
            last = (at, own, host, broker)

    def _broker_cpu(self) -> float | None:
        return None if self.broker_pid is None else _cpu_s(self.broker_pid)


def _share(used: float | None, before: float | None, wall: float) -> int | None:
    if used is None or before is None or used < before:
        return None
    return round(100 * (used - before) / wall)


async def figures(args: argparse.Namespace) -> dict[str, Any]:
    gateway = Gateway(args.drives)
    with tempfile.TemporaryDirectory() as directory:
        broker = Mosquitto(Path(directory))
        await broker.start()
        try:
            return await _outage(args, gateway, broker, Path(directory))
        finally:
            await broker.kill()


async def _outage(
    args: argparse.Namespace, gateway: Gateway, broker: Mosquitto, directory: Path
) -> dict[str, Any]:
    made: dict[int, float] = {}  # change number → when made
    counts = [0] * args.drives
    phases: dict[str, list[int]] = {"warmup": [], "outage": [], "drain": []}
    host: HostHere | HostProcess = (
        HostHere(args.drives, broker.port)
        if args.host_in_process
        else HostProcess(args.drives, broker.port, directory)
    )

    async def produce() -> None:
        period = 1.0 / args.rate
        due = now()
        k = 0
        while True:
            index = k % args.drives
            counts[index] += 1
            number = counts[index] * args.drives + index
            made[number] = now()
            phases[timeline.phase].append(number)
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
        primary_host_id=HOST_ID,
        store=str(store),
        reconnect_min_s=0.2,
        reconnect_max_s=1.0,
    )
    for plan in gateway.plans:  # online from the start: born at the first connection
        gateway.reply(plan, 0.0)
    node_gateway: Any = gateway  # the parts of the Gateway protocol the adapter uses
    await host.start()
    async with SparkplugAdapter(settings, node_gateway) as node:
        timeline = Timeline(args.sample_s, node, host)
        assert broker.process is not None
        timeline.broker_pid = broker.process.pid
        sampler = asyncio.create_task(timeline.run())
        while node.node.births == 0:  # noqa: ASYNC110  # born once the host's STATE came
            await asyncio.sleep(0.05)
        producer = asyncio.create_task(produce())
        await asyncio.sleep(args.warmup_s)
        _say(f"outage of {args.outage_s} s")
        timeline.phase = "outage"
        outage_at = now()
        await broker.kill()
        largest = 0
        while now() - outage_at < args.outage_s:
            await asyncio.sleep(1.0)
            largest = max(largest, await node.forward.size_bytes())
        await broker.start()
        assert broker.process is not None
        timeline.broker_pid = broker.process.pid
        _say("broker back: draining")
        timeline.phase = "drain"
        drain_at = now()
        outage = phases["outage"]
        replayed, last_missing, stalled = -1, -1, 0
        while now() - drain_at < args.drain_limit_s:
            await asyncio.sleep(1.0)
            largest = max(largest, await node.forward.size_bytes())
            missing = await host.missing(outage)
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
        sampler.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await sampler
        received = await host.finish()
        replayed, unborn = node.forward.replayed, node.forward.unborn
        recorded, dropped = node.forward.last_n, node.forward.writer.dropped
    file_bytes = sum(p.stat().st_size for p in store.parent.glob("sparkplug.db*"))

    live: dict[int, float] = dict(received["live"])
    seen: dict[int, int] = dict(received["seen"])
    history: list[tuple[int, int]] = [(i, n) for i, n in received["history"]]
    delivered = [n for n in outage if n in seen]
    per_drive: list[list[int]] = [[] for _ in range(args.drives)]
    for index, number in history:
        per_drive[index].append(number)
    in_order = all(a < b for numbers in per_drive for a, b in itertools.pairwise(numbers))

    def latencies(numbers: list[int]) -> list[float]:
        return [live[n] - made[n] for n in numbers if n in live]

    _windows(timeline, live, made)
    return {
        **results_file.provenance("sparkplug_outage"),
        "load_average": list(os.getloadavg()),
        "settings": {
            "rate_per_s": args.rate,
            "outage_s": args.outage_s,
            "drives": args.drives,
            "warmup_s": args.warmup_s,
            "host": "in the node's process" if args.host_in_process else "a process of its own",
        },
        "changes_made": {name: len(numbers) for name, numbers in phases.items()},
        "outage_changes_delivered_pct": 100.0 * len(delivered) / max(1, len(outage)),
        "outage_changes_missing": len(outage) - len(delivered),
        "missing_sample": [n for n in outage if n not in seen][:20],
        "history_in_order_per_drive": in_order,
        "history_received": len(history),
        "duplicates": sum(c - 1 for c in seen.values() if c > 1),
        "changes_taken_in": recorded,
        "store_dropped": dropped,
        "replayed_rows": replayed,
        "unborn_rows": unborn,
        "drain_s": drained_s,
        "live_latency_warmup": _percentiles(latencies(phases["warmup"])),
        "live_latency_during_drain": _percentiles(latencies(phases["drain"])),
        "store_used_bytes_max": largest,
        "store_file_bytes_after": file_bytes,
        "timeline": [s for s in timeline.samples if s["phase"] != "outage"],
    }


def _windows(timeline: Timeline, live: dict[int, float], made: dict[int, float]) -> None:
    """Each timeline sample gets the live latency (p99, max) of what arrived in its window."""
    windows: dict[int, list[float]] = {}
    for number, arrived in live.items():
        at = int((arrived - timeline.started) // timeline.period_s)
        windows.setdefault(at, []).append(arrived - made[number])
    for sample in timeline.samples:
        window = windows.get(round(sample["t_s"] / timeline.period_s) - 1, [])
        figures = _percentiles(window)
        sample["live_p99_ms"] = None if figures["p99_ms"] is None else round(figures["p99_ms"])
        sample["live_max_ms"] = None if figures["max_ms"] is None else round(figures["max_ms"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=1000.0, help="changes per second")
    parser.add_argument("--outage-s", type=float, default=60.0)
    parser.add_argument("--warmup-s", type=float, default=5.0)
    parser.add_argument("--drain-limit-s", type=float, default=600.0)
    parser.add_argument("--drives", type=int, default=10)
    parser.add_argument("--sample-s", type=float, default=5.0, help="the timeline's period")
    parser.add_argument(
        "--host-in-process", action="store_true", help="the host in the node's process"
    )
    parser.add_argument("--serve-host", type=int, metavar="PORT", help=argparse.SUPPRESS)
    parser.add_argument(
        "--output",
        type=Path,
        default=Path(__file__).parent / "results" / "sparkplug_outage.json",
    )
    args = parser.parse_args()
    if args.serve_host is not None:
        asyncio.run(serve_host(args.serve_host, args.drives))
        return
    results_file.run_and_write(figures(args), args.output)


if __name__ == "__main__":
    main()
