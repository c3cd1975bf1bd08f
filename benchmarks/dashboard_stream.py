"""What the dashboard's stream costs on the demo: messages and bytes per second, daemon CPU.

Run: ``python benchmarks/dashboard_stream.py [--duration 20] [--clients 1] [--output FILE]``.

The demo (``fcmaster run`` with no ``--config``: two simulated lines, ten drives) runs as a
subprocess on a free port, as :mod:`daemon_footprint` starts it. Once its drives show, two
windows of ``--duration`` seconds each are measured back to back:

* **idle**: nobody is connected; the daemon's CPU (utime + stime from ``/proc/PID/stat``)
  is what polling and the fleet state cost by themselves;
* **streaming**: ``--clients`` WebSocket clients read ``/api/v1/stream`` as a browser
  would; each message is counted by type with its bytes, and each ``drive`` message is
  compared with the previous one of the same drive: one that differs only in its times
  (``updated_at``, ``output_frequency_updated_at``, the values' ``updated_at``) told a
  subscriber nothing new.

Reported per window: daemon CPU as a share of one core, the lines' transactions per second
(``/api/v1/buses``); for streaming also messages/s and KB/s per client, drive messages/s,
and how many drive messages repeated an unchanged state. The machine's load average goes
with the figures. Linux only (``/proc``).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any, Final

import results_file
from daemon_footprint import _cpu_s, _free_port, _requests, _wait_for_fleet
from websockets.asyncio.client import connect

DEFAULT_OUTPUT: Final = Path(__file__).resolve().parent / "results" / "dashboard_stream.json"
EXIT_S: Final = 10.0


def _without_times(drive: dict[str, Any]) -> dict[str, Any]:
    """A drive state with every reading time taken out, to tell news from a fresh stamp."""
    out = {k: v for k, v in drive.items() if k not in ("updated_at", "output_frequency_updated_at")}
    out["values"] = {
        name: {k: v for k, v in value.items() if k != "updated_at"}
        for name, value in drive.get("values", {}).items()
    }
    return out


async def _client(url: str, until: float, tally: dict[str, Any]) -> None:
    types: Counter[str] = tally["types"]
    last: dict[str, dict[str, Any]] = {}
    async with connect(url, max_size=None) as ws:
        while (left := until - time.monotonic()) > 0:
            try:
                text = await asyncio.wait_for(ws.recv(), timeout=left)
            except TimeoutError:
                break
            message = json.loads(text)
            kind = message["type"]
            if kind == "snapshot":
                last = {d["name"]: _without_times(d) for d in message["drives"]}
                continue
            types[kind] += 1
            tally["bytes"] += len(text.encode() if isinstance(text, str) else text)
            if kind == "drive":
                drive = message["drive"]
                bare = _without_times(drive)
                if last.get(drive["name"]) == bare:
                    tally["unchanged"] += 1
                last[drive["name"]] = bare


async def _stream(url: str, clients: int, duration_s: float) -> list[dict[str, Any]]:
    until = time.monotonic() + duration_s
    tallies: list[dict[str, Any]] = [
        {"types": Counter(), "bytes": 0, "unchanged": 0} for _ in range(clients)
    ]
    await asyncio.gather(*(_client(url, until, t) for t in tallies))
    return tallies


def _window(base: str, pid: int, run: Any) -> dict[str, Any]:
    counts_start = _requests(base)
    cpu_start, started = _cpu_s(pid), time.monotonic()
    extra = run()
    window_s = time.monotonic() - started
    cpu_s = _cpu_s(pid) - cpu_start
    counts_end = _requests(base)
    transactions = sum(
        counts_end[name]["requests"] - c["requests"] for name, c in counts_start.items()
    )
    return {
        "window_s": window_s,
        "cpu_pct_of_one_core": cpu_s / window_s * 100.0,
        "transactions_per_s": transactions / window_s,
        **extra(window_s),
    }


def measure(duration_s: float, clients: int) -> dict[str, Any]:
    """Run the demo, measure an idle and a streaming window, stop it."""
    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    url = f"ws://127.0.0.1:{port}/api/v1/stream"
    pause = threading.Event()  # never set: a sleep
    with tempfile.TemporaryDirectory(prefix="fcmaster-stream-") as cwd:
        process = subprocess.Popen(
            [sys.executable, "-m", "fcmaster", "run", "--http-listen", f"127.0.0.1:{port}"],
            cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )  # fmt: skip
        try:
            _wait_for_fleet(base, process, pause)
            pause.wait(2.0)  # past the start-up burst (adoption, first condition reads)

            def idle() -> Any:
                pause.wait(duration_s)
                return lambda _s: {}

            def streaming() -> Any:
                tallies = asyncio.run(_stream(url, clients, duration_s))

                def figures(window_s: float) -> dict[str, Any]:
                    n = len(tallies)
                    types: Counter[str] = sum((t["types"] for t in tallies), Counter())
                    return {
                        "clients": n,
                        "messages_per_s_per_client": sum(types.values()) / n / window_s,
                        "kb_per_s_per_client": sum(t["bytes"] for t in tallies)
                        / n
                        / window_s
                        / 1e3,
                        "drive_messages_per_s_per_client": types["drive"] / n / window_s,
                        "drive_messages": types["drive"] // n,
                        "unchanged_drive_messages": sum(t["unchanged"] for t in tallies) // n,
                        "messages_by_type": {k: v // n for k, v in sorted(types.items())},
                    }

                return figures

            results = {
                "idle": _window(base, process.pid, idle),
                "streaming": _window(base, process.pid, streaming),
            }
            process.send_signal(signal.SIGTERM)
            results["exit_code"] = process.wait(EXIT_S)
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
    return results


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=20.0, help="seconds per window")
    parser.add_argument("--clients", type=int, default=1, help="stream clients at once")
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT, help="the JSON results")
    args = parser.parse_args()
    load_before = os.getloadavg()
    figures = measure(args.duration, args.clients)
    results = {
        **results_file.provenance("dashboard_stream"),
        "load_average_before": load_before,
        "load_average_after": os.getloadavg(),
        **figures,
    }
    results_file.write(args.output, results)
    print(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
