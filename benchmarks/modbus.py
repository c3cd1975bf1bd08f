"""Modbus TCP polling load: what 20 PLCs at 10 Hz cost the line, and how fast they are answered.

Run: ``python benchmarks/modbus.py [--clients 20] [--rate-hz 10] [--seconds 15]
[--drives 8] [--baudrate 115200] [--response-delay-ms 10] [--out PATH]`` (about a minute;
results in ``benchmarks/results/modbus.json`` by default).

A daemon (:class:`fcmaster.service.Service`, fcmaster's precise event loop) polls simulated
FC drives on an in-process ``sim://`` line in real time, with the Modbus server on a free
loopback port. The line's transaction rate (the master's request counter over wall time)
is measured three times for ``--seconds`` each: without clients, with ``--clients`` Modbus
clients polling, and without clients again; the change is the loaded rate against the
mean of the two quiet ones. The clients run in a second process, as PLCs are other
machines: each keeps one connection and, every ``1 / --rate-hz`` seconds on its own
schedule (random phase), reads a whole unit — input registers 0 to the end of the
monitored values (FC 4) — of the drives in turn, timing each answer with
``perf_counter`` from just before the request is written to when the answer is whole.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import random
import socket
import statistics
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import results_file

from fcmaster.clock import new_event_loop
from fcmaster.config import parse
from fcmaster.service import Service

now = time.perf_counter
REGISTERS = 44  # a drive with FC's default monitor: state block + 7 values × 4 registers


def fleet(drives: int, baudrate: int, delay_ms: float, port: int) -> str:
    lines = "\n".join(
        f"      - {{name: d{a}, address: {a}, control: bus}}" for a in range(1, drives + 1)
    )
    return (
        f"buses:\n  - name: line1\n    port: sim://line1\n    baudrate: {baudrate}\n"
        f"    response_delay_ms: {delay_ms}\n"
        f"    simulation: {{response_delay_ms: {delay_ms}}}\n"
        f"    drives:\n{lines}\nmodbus: {{listen: 127.0.0.1:{port}}}\n"
    )


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


# -- the clients (second process) ---------------------------------------------------------


async def client(port: int, units: int, rate_hz: float, until: float, out: list[float]) -> int:
    """One PLC: poll until ``until``; latencies into ``out``; returns exceptions seen."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    period = 1.0 / rate_hz
    due = now() + random.random() * period
    transaction = errors = 0
    try:
        while due < until:
            await asyncio.sleep(max(0.0, due - now()))
            transaction = (transaction + 1) & 0xFFFF
            unit = 1 + transaction % units
            request = struct.pack(">HHHBBHH", transaction, 0, 6, unit, 4, 0, REGISTERS)
            sent = now()
            writer.write(request)
            header = await reader.readexactly(7)
            length = struct.unpack(">HHHB", header)[2]
            body = await reader.readexactly(length - 1)
            out.append(now() - sent)
            if body[0] & 0x80 or struct.unpack_from(">H", header)[0] != transaction:
                errors += 1
            due += period
    finally:
        writer.close()
    return errors


async def clients(port: int, count: int, units: int, rate_hz: float, seconds: float) -> None:
    latencies: list[float] = []
    until = now() + seconds
    errors = await asyncio.gather(
        *(client(port, units, rate_hz, until, latencies) for _ in range(count))
    )
    print(json.dumps({"latencies": latencies, "errors": sum(errors)}))


# -- the daemon (this process) ----------------------------------------------------------


async def transaction_rate(service: Service, seconds: float) -> float:
    master = service.masters["line1"]
    first, started = master.stats.requests, now()
    await asyncio.sleep(seconds)
    return (master.stats.requests - first) / (now() - started)


async def measure(args: argparse.Namespace) -> dict[str, Any]:
    port = free_port()
    service = Service(parse(fleet(args.drives, args.baudrate, args.response_delay_ms, port)))
    running = asyncio.create_task(service.run(install_signals=False))
    try:
        await asyncio.sleep(2.0)  # every drive online, the rotation settled
        quiet_before = await transaction_rate(service, args.seconds)
        load = await asyncio.create_subprocess_exec(
            sys.executable, __file__, "--serve-clients", str(port),
            "--clients", str(args.clients), "--drives", str(args.drives),
            "--rate-hz", str(args.rate_hz), "--seconds", str(args.seconds + 2.0),
            stdout=subprocess.PIPE,
        )  # fmt: skip
        await asyncio.sleep(1.0)  # connected and polling
        loaded = await transaction_rate(service, args.seconds)
        output, _ = await load.communicate()
        quiet_after = await transaction_rate(service, args.seconds)
    finally:
        service.stop()
        await running
    polled = json.loads(output)
    latencies = sorted(polled["latencies"])
    quiet = (quiet_before + quiet_after) / 2
    ms = [x * 1000 for x in latencies]
    return {
        **results_file.provenance("modbus"),
        "clients": args.clients,
        "rate_hz": args.rate_hz,
        "drives": args.drives,
        "baudrate": args.baudrate,
        "response_delay_ms": args.response_delay_ms,
        "seconds_per_phase": args.seconds,
        "transactions_per_s": {
            "quiet_before": round(quiet_before, 1),
            "loaded": round(loaded, 1),
            "quiet_after": round(quiet_after, 1),
            "change_pct": round((loaded / quiet - 1) * 100, 2),
        },
        "answers": {
            "count": len(ms),
            "exceptions": polled["errors"],
            "p50_ms": round(statistics.median(ms), 3),
            "p99_ms": round(ms[int(0.99 * (len(ms) - 1))], 3),
            "max_ms": round(ms[-1], 3),
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, default=20)
    parser.add_argument("--rate-hz", type=float, default=10.0)
    parser.add_argument("--seconds", type=float, default=15.0)
    parser.add_argument("--drives", type=int, default=8)
    parser.add_argument("--baudrate", type=int, default=115200)
    parser.add_argument(
        "--response-delay-ms", type=float, default=10.0, help="the drives' (FC 8-35; default 10)"
    )
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/modbus.json"))
    parser.add_argument("--serve-clients", type=int, metavar="PORT", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.serve_clients:
        asyncio.run(clients(args.serve_clients, args.clients, args.drives, args.rate_hz,
                            args.seconds))  # fmt: skip
        return
    loadavg = Path("/proc/loadavg").read_text().split()[:3]
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        results = runner.run(measure(args))
    results["loadavg_before"] = loadavg
    results["loadavg_after"] = Path("/proc/loadavg").read_text().split()[:3]
    print(json.dumps(results, indent=2))
    results_file.write(args.out, results)


if __name__ == "__main__":
    main()
