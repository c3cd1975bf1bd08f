"""Modbus TCP polling load: what 20 PLCs at 10 Hz cost the line, and how fast they are answered.

Run: ``python benchmarks/modbus.py [--clients 20] [--rate-hz 10] [--seconds 5] [--cycles 6]
[--drives 8] [--baudrate 115200] [--response-delay-ms 10] [--out PATH]`` (about a minute;
results in ``benchmarks/results/modbus.json`` by default).

A daemon (:class:`fcmaster.service.Service`, fcmaster's precise event loop) polls simulated
FC drives on an in-process ``sim://`` line in real time, with the Modbus server on a free
loopback port. The line's transaction rate (the master's request counter over wall time)
is measured in alternating windows of ``--seconds``: quiet, then loaded with ``--clients``
Modbus clients polling, ``--cycles`` times; the change is the mean loaded rate against the
mean quiet one, and the spread among the quiet windows says how much of it is noise (other
work on the machine). The clients run in a second process, as PLCs are other machines:
each keeps one connection open throughout and, in the loaded windows, every
``1 / --rate-hz`` seconds on its own schedule (random phase), reads a whole unit — input
registers 0 to the end of the monitored values (FC 4) — of the drives in turn, timing each
answer with ``perf_counter`` from just before the request is written to when the answer is whole.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
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


def loaded_window(epoch: float, window_s: float) -> bool:
    """Whether wall-clock time now falls in a loaded window (odd windows from ``epoch``)."""
    k = math.floor((time.time() - epoch) / window_s)
    return k >= 0 and k % 2 == 1


async def client(
    port: int, units: int, rate_hz: float, epoch: float, window_s: float, windows: int,
    out: list[float],
) -> int:  # fmt: skip
    """One PLC: poll in the loaded windows only; latencies into ``out``; exceptions seen."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    period = 1.0 / rate_hz
    due = now() + random.random() * period
    until = epoch + windows * window_s
    transaction = errors = 0
    try:
        while time.time() < until:
            await asyncio.sleep(max(0.0, due - now()))
            due += period
            if not loaded_window(epoch, window_s):
                continue  # connected but quiet, as a PLC between its polls
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
    finally:
        writer.close()
    return errors


async def clients(args: argparse.Namespace) -> None:
    latencies: list[float] = []
    epoch, window_s, windows = args.epoch, args.seconds, 2 * args.cycles
    polls = [
        client(args.serve_clients, args.drives, args.rate_hz, epoch, window_s, windows, latencies)
        for _ in range(args.clients)
    ]
    errors = await asyncio.gather(*polls)
    print(json.dumps({"latencies": latencies, "errors": sum(errors)}))


# -- the daemon (this process) ----------------------------------------------------------


async def window_rates(
    service: Service, epoch: float, window_s: float, windows: int
) -> list[float]:
    """The line's transactions per second in each window (the master's request counter)."""
    master = service.masters["line1"]
    rates = []
    for k in range(windows):
        await asyncio.sleep(max(0.0, epoch + k * window_s - time.time()))
        first, started = master.stats.requests, now()
        await asyncio.sleep(max(0.0, epoch + (k + 1) * window_s - time.time()))
        rates.append((master.stats.requests - first) / (now() - started))
    return rates


async def measure(args: argparse.Namespace) -> dict[str, Any]:
    port = free_port()
    service = Service(parse(fleet(args.drives, args.baudrate, args.response_delay_ms, port)))
    running = asyncio.create_task(service.run(install_signals=False))
    epoch = time.time() + 3.0  # every drive online and the clients connected by then
    windows = 2 * args.cycles
    try:
        load = await asyncio.create_subprocess_exec(
            sys.executable, __file__, "--serve-clients", str(port), "--epoch", repr(epoch),
            "--clients", str(args.clients), "--drives", str(args.drives),
            "--rate-hz", str(args.rate_hz), "--seconds", str(args.seconds),
            "--cycles", str(args.cycles), stdout=subprocess.PIPE,
        )  # fmt: skip
        rates = await window_rates(service, epoch, args.seconds, windows)
        output, _ = await load.communicate()
    finally:
        service.stop()
        await running
    polled = json.loads(output)
    quiet, loaded = rates[0::2], rates[1::2]
    ms = sorted(x * 1000 for x in polled["latencies"])
    return {
        **results_file.provenance("modbus"),
        "clients": args.clients,
        "rate_hz": args.rate_hz,
        "drives": args.drives,
        "baudrate": args.baudrate,
        "response_delay_ms": args.response_delay_ms,
        "window_s": args.seconds,
        "transactions_per_s": {
            "quiet_windows": [round(r, 1) for r in quiet],
            "loaded_windows": [round(r, 1) for r in loaded],
            "quiet_mean": round(statistics.mean(quiet), 2),
            "loaded_mean": round(statistics.mean(loaded), 2),
            "change_pct": round((statistics.mean(loaded) / statistics.mean(quiet) - 1) * 100, 2),
            # how much quiet windows differ among themselves: the noise floor of change_pct
            "quiet_spread_pct": round((max(quiet) - min(quiet)) / statistics.mean(quiet) * 100, 2),
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
    parser.add_argument("--seconds", type=float, default=5.0, help="length of one window")
    parser.add_argument("--cycles", type=int, default=6, help="quiet + loaded window pairs")
    parser.add_argument("--drives", type=int, default=8)
    parser.add_argument("--baudrate", type=int, default=115200)
    parser.add_argument(
        "--response-delay-ms", type=float, default=10.0, help="the drives' (FC 8-35; default 10)"
    )
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/modbus.json"))
    parser.add_argument("--serve-clients", type=int, metavar="PORT", help=argparse.SUPPRESS)
    parser.add_argument("--epoch", type=float, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.serve_clients:
        asyncio.run(clients(args))
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
