"""Line rate behind a USB adapter's latency timer: none (a pty), 1 ms and 16 ms.

Run: ``python benchmarks/adapter_latency.py [--duration S] [--output PATH]`` (default 5 s
per case, about 20 s in all).

For each case, ``fcmaster sim`` serves 8 FC drives (10 ms response delay) on a pty in its
own process, with ``--adapter-latency-ms`` when the case has one: the simulated adapter
holds what reaches the master until its timer ticks, as an FTDI chip does. The daemon's
real bus master (:class:`~fcmaster.service.Service`, no adapters) polls them over the real
serial transport; after a 1 s warm-up, replies per second over the window are the line
rate. Cases run at 19200 and 115200 baud (8E1): at 115200 a transaction fits in well under
16 ms, so the timer, not the line, sets the pace.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import sys
import time
from pathlib import Path
from typing import Any

import results_file

from fcmaster import logsetup
from fcmaster.clock import new_event_loop
from fcmaster.config import parse
from fcmaster.service import Service

DRIVES = 8
WARM_UP_S = 1.0
CONFIG = """
buses:
  - name: line1
    port: {port}
    baudrate: {baudrate}
    drives:
{drives}
"""


async def run_case(baudrate: int, latency_ms: float | None, duration_s: float) -> dict[str, Any]:
    args = ["-m", "fcmaster", "sim", "--addresses", f"1-{DRIVES}", "--baudrate", str(baudrate)]
    if latency_ms is not None:
        args += ["--adapter-latency-ms", str(latency_ms)]
    sim = await asyncio.create_subprocess_exec(
        sys.executable, *args, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.DEVNULL
    )
    try:
        assert sim.stdout is not None
        _, port = (await asyncio.wait_for(sim.stdout.readline(), 30)).decode().split()
        drives = "\n".join(f"      - {{name: d{a}, address: {a}}}" for a in range(1, DRIVES + 1))
        service = Service(parse(CONFIG.format(port=port, baudrate=baudrate, drives=drives)))
        runner = asyncio.create_task(service.run(install_signals=False))
        await asyncio.sleep(WARM_UP_S)
        start_stats, started = service.lines()[0].stats, time.monotonic()
        cpu = time.process_time()
        await asyncio.sleep(duration_s)
        end_stats, elapsed = service.lines()[0].stats, time.monotonic() - started
        cpu = time.process_time() - cpu
        service.stop()
        await asyncio.wait_for(runner, 10)
    finally:
        sim.terminate()
        await sim.wait()
    replies = end_stats["replies"] - start_stats["replies"]
    return {
        "baudrate": baudrate,
        "adapter_latency_ms": latency_ms,
        "drives": DRIVES,
        "seconds": round(elapsed, 3),
        "replies_per_s": round(replies / elapsed, 1),
        "timeouts": end_stats["timeouts"] - start_stats["timeouts"],
        "master_cpu_s": round(cpu, 3),
    }


async def main_async(duration_s: float) -> list[dict[str, Any]]:
    rows = []
    for baudrate in (19200, 115200):
        for latency in (None, 1.0, 16.0):
            row = await run_case(baudrate, latency, duration_s)
            label = "none (pty)" if latency is None else f"{latency:g} ms"
            print(
                f"{baudrate:>6} baud  adapter {label:<10}  {row['replies_per_s']:>6.1f} replies/s"
                f"  timeouts {row['timeouts']}",
                flush=True,
            )
            rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=5.0, help="seconds per case")
    parser.add_argument(
        "--output", type=Path, default=Path(__file__).parent / "results" / "adapter_latency.json"
    )
    args = parser.parse_args(argv)
    logsetup.configure("warning")
    load_before = os.getloadavg()
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        rows = runner.run(main_async(args.duration))
    results = {
        **results_file.provenance("adapter_latency"),
        "loadavg_before": load_before,
        "loadavg_after": os.getloadavg(),
        "cases": rows,
    }
    results_file.write(args.output, results)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
