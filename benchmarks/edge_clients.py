"""What clients at the edges cost the line: silent WebSocket streams, and a kept-open HTTP
connection's answer times.

Run: ``python benchmarks/edge_clients.py [--streams 500] [--window 8] [--cycles 3]
[--output FILE]`` (about a minute; results in ``benchmarks/results/edge_clients.json``).
The Modbus read flood's figure comes from ``python benchmarks/modbus.py --clients 30
--rate-hz 100000`` (each client asks again as soon as it is answered).

The demo (``fcmaster run`` with no ``--config``) runs as a subprocess on a free port, as
:mod:`dashboard_stream` starts it. Then:

* **streams**: windows of ``--window`` seconds, alternately quiet and with ``--streams``
  WebSocket streams opened over raw sockets that read the answer's status line and nothing
  more (a receive buffer of 4 KB, so their backlog fills), opened a second before the window
  and closed after it, ``--cycles`` times. Per window the
  lines' transactions per second (``/api/v1/buses``) and the daemon's CPU; for the loaded
  ones how many streams were let in (101) and refused (503). The change is the mean loaded
  rate against the mean quiet one; the spread among quiet windows is the noise floor.
* **keep-alive**: 20 sequential ``GET /api/v1/drives`` on one kept-open connection
  (``http.client``), each timed from the request's first byte to its answer's last.

The machine's load average goes with the figures. Linux only (``/proc``).
"""

from __future__ import annotations

import argparse
import base64
import http.client
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Final

import results_file
from daemon_footprint import _free_port, _wait_for_fleet
from dashboard_stream import _window

DEFAULT_OUTPUT: Final = Path(__file__).resolve().parent / "results" / "edge_clients.json"
EXIT_S: Final = 10.0


def _silent_streams(port: int, count: int) -> tuple[list[socket.socket], dict[int, int]]:
    """``count`` streams asked for and never read; the sockets and the statuses answered."""
    opened, statuses = [], {}
    for _ in range(count):
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.settimeout(5)
        try:
            sock.connect(("127.0.0.1", port))
            key = base64.b64encode(os.urandom(16)).decode()
            sock.sendall(
                (
                    f"GET /api/v1/stream HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
                    f"Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                    "Sec-WebSocket-Version: 13\r\n\r\n"
                ).encode()
            )
            status = int(sock.recv(12).split()[1])
        except (OSError, IndexError, ValueError):
            status = 0  # closed or reset at once
        statuses[status] = statuses.get(status, 0) + 1
        opened.append(sock)
    return opened, statuses


def _keep_alive(port: int, requests: int = 20) -> dict[str, Any]:
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    took_ms = []
    for _ in range(requests):
        started = time.perf_counter()
        connection.request("GET", "/api/v1/drives")
        connection.getresponse().read()
        took_ms.append((time.perf_counter() - started) * 1000)
    connection.close()
    return {
        "requests": requests,
        "first_ms": round(took_ms[0], 2),
        "later_median_ms": round(statistics.median(took_ms[1:]), 2),
        "later_max_ms": round(max(took_ms[1:]), 2),
        "all_ms": [round(t, 2) for t in took_ms],
    }


def measure(streams: int, window_s: float, cycles: int) -> dict[str, Any]:
    """Run the demo, measure quiet and loaded windows and the keep-alive answers, stop it."""
    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    pause = threading.Event()  # never set: a sleep
    with tempfile.TemporaryDirectory(prefix="fcmaster-edges-") as cwd:
        process = subprocess.Popen(
            [sys.executable, "-m", "fcmaster", "run", "--http-listen", f"127.0.0.1:{port}"],
            cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )  # fmt: skip
        try:
            _wait_for_fleet(base, process, pause)
            pause.wait(2.0)  # past the start-up burst (adoption, first condition reads)
            quiet, loaded = [], []
            for _ in range(cycles):

                def idle() -> Any:
                    pause.wait(window_s)
                    return lambda _s: {}

                quiet.append(_window(base, process.pid, idle))
                opened, statuses = _silent_streams(port, streams)
                pause.wait(1.0)  # the window is the streams held open, not their opening
                window = _window(base, process.pid, idle)
                for sock in opened:
                    sock.close()
                loaded.append({**window, "statuses": statuses})
            keep_alive = _keep_alive(port)
            process.terminate()
            process.wait(EXIT_S)
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
    quiet_rates = [w["transactions_per_s"] for w in quiet]
    loaded_rates = [w["transactions_per_s"] for w in loaded]
    return {
        "streams": {
            "silent_streams": streams,
            "window_s": window_s,
            "quiet_windows": quiet,
            "loaded_windows": loaded,
            "quiet_mean_tps": round(statistics.mean(quiet_rates), 2),
            "loaded_mean_tps": round(statistics.mean(loaded_rates), 2),
            "change_pct": round(
                (statistics.mean(loaded_rates) / statistics.mean(quiet_rates) - 1) * 100, 2
            ),
            "quiet_spread_pct": round(
                (max(quiet_rates) - min(quiet_rates)) / statistics.mean(quiet_rates) * 100, 2
            ),
        },
        "keep_alive": keep_alive,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--streams", type=int, default=500)
    parser.add_argument("--window", type=float, default=8.0, help="seconds per window")
    parser.add_argument("--cycles", type=int, default=3, help="quiet + loaded window pairs")
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT, help="the JSON results")
    args = parser.parse_args()
    load_before = os.getloadavg()
    figures = measure(args.streams, args.window, args.cycles)
    results = {
        **results_file.provenance("edge_clients"),
        "load_average_before": load_before,
        "load_average_after": os.getloadavg(),
        **figures,
    }
    results_file.write(args.output, results)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
