"""An operator's stop while connections are held open to lock operators out.

Run: ``python benchmarks/http_flood.py [--idle 300] [--half-open 100] [--stops 10]``

`fcmaster run` (a subprocess, as deployed) serves a simulated line (``sim://``, 115200
baud, two ``control: bus`` drives) and its HTTP API. This script opens ``--idle``
connections that send nothing and ``--half-open`` ones that send half a request head,
from many loopback addresses (127.0.0.2 and up, as many hosts on a plant network would),
(``--hosts``), and keeps them: a connection the server closes is opened again after
``--reconnect-s`` (0: at once, which is harder than holding them, since each
reconnection takes an idle one's place again; negative: never). Meanwhile an
operator sends stops from new connections, one at a time. Each stop's time is from its
connect to its answer; its outcome ``done`` means the drive acknowledged the telegram,
so the stop was on the wire within that time. Reported: the stops' times (median, max),
their outcomes, and how many flood connections the server closed (made room or timed
out). Target: every stop answered ``done`` within 1 s.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import socket
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

TOKEN = "bench-operator-0123456789abcdef"
CONFIG = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    drives:
      - {{name: pump-1, address: 1, control: bus}}
      - {{name: pump-2, address: 2, control: bus}}
http:
  listen: 127.0.0.1:{port}
  tokens:
    - {{name: ops, role: operator, token: {token}}}
logging: {{level: warning, format: json}}
"""


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


class Flood:
    """Connections held open; each one the server closes is opened again."""

    def __init__(
        self, port: int, idle: int, half_open: int, hosts: int, reconnect_s: float | None
    ) -> None:
        self.port = port
        self.reconnect_s = reconnect_s
        self.hosts = hosts
        self.all_open = asyncio.Event()
        self.idle = idle
        self.half_open = half_open
        self.closed_by_server = 0
        self.open_now = 0
        self._tasks: list[asyncio.Task[None]] = []

    async def start(self) -> None:
        for n in range(self.idle + self.half_open):
            first = b"" if n < self.idle else b"POST /api/v1/drives/pump-1/commands HTTP/1.1\r\nHo"
            self._tasks.append(asyncio.create_task(self._hold(n, first)))
        await self.all_open.wait()

    async def _hold(self, n: int, first: bytes) -> None:
        counted = False
        while True:
            try:
                reader, writer = await asyncio.open_connection(
                    "127.0.0.1", self.port, local_addr=(_address(n % self.hosts), 0)
                )
            except OSError:
                await asyncio.sleep(0.05)
                continue
            if not counted:
                self.open_now += 1
                counted = True
                if self.open_now == self.idle + self.half_open:
                    self.all_open.set()
            try:
                if first:
                    writer.write(first)
                await reader.read()  # until the server closes it
                self.closed_by_server += 1
            except ConnectionError:
                self.closed_by_server += 1
            finally:
                writer.close()
            if self.reconnect_s is None:
                return
            await asyncio.sleep(self.reconnect_s)

    async def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)


def _address(n: int) -> str:
    """The n-th flood address: 127.0.0.2, 127.0.0.3, … 127.0.1.1, …"""
    n += 2
    return f"127.0.{n // 256}.{n % 256}"


async def _stop(port: int) -> tuple[float, str, int]:
    started = time.perf_counter()
    async with httpx.AsyncClient(
        base_url=f"http://127.0.0.1:{port}",
        headers={"Authorization": f"Bearer {TOKEN}"},
        timeout=10,
    ) as client:
        try:
            response = await client.post("/api/v1/drives/pump-1/commands", json={"action": "stop"})
        except httpx.HTTPError as exc:
            return time.perf_counter() - started, type(exc).__name__, 0
    return time.perf_counter() - started, response.json().get("outcome", "?"), response.status_code


async def main(
    idle: int, half_open: int, stops: int, hosts: int, reconnect_s: float | None
) -> dict[str, Any]:
    port = _free_port()
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "bench.yaml"
        config.write_text(CONFIG.format(port=port, token=TOKEN))
        daemon = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "fcmaster", "run", "--config", str(config),
            stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL,
        )  # fmt: skip
        try:
            for _ in range(300):  # up to 30 s for a cold start
                with contextlib.suppress(httpx.HTTPError):
                    async with httpx.AsyncClient() as client:
                        r = await client.get(
                            f"http://127.0.0.1:{port}/api/v1/drives",
                            headers={"Authorization": f"Bearer {TOKEN}"},
                        )
                        if r.status_code == 200 and all(d["online"] for d in r.json()):
                            break
                await asyncio.sleep(0.1)
            baseline = [await _stop(port) for _ in range(3)]
            flood = Flood(port, idle, half_open, hosts, reconnect_s)
            await flood.start()
            results = []
            for _ in range(stops):
                results.append(await _stop(port))
                await asyncio.sleep(0.2)
            closed = flood.closed_by_server
            await flood.stop()
        finally:
            daemon.terminate()
            await daemon.wait()
    times = [t for t, _, _ in results]
    return {
        "idle": idle,
        "half_open": half_open,
        "flood_hosts": hosts,
        "reconnect_s": reconnect_s,
        "stops": len(results),
        "outcomes": sorted({f"{o} {s}" for _, o, s in results}),
        "stop_s_median": round(statistics.median(times), 4),
        "stop_s_max": round(max(times), 4),
        "baseline_stop_s_median": round(statistics.median(t for t, _, _ in baseline), 4),
        "flood_connections_closed_by_server": closed,
        "loadavg": os.getloadavg(),
    }


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--idle", type=int, default=300)
    parser.add_argument("--half-open", type=int, default=100)
    parser.add_argument("--stops", type=int, default=10)
    parser.add_argument("--hosts", type=int, default=200, help="loopback addresses to flood from")
    parser.add_argument(
        "--reconnect-s",
        type=float,
        default=0.0,
        help="reopen a connection the server closed after this long (negative: never)",
    )
    args = parser.parse_args()
    reconnect = None if args.reconnect_s < 0 else args.reconnect_s
    figures = asyncio.run(main(args.idle, args.half_open, args.stops, args.hosts, reconnect))
    print(json.dumps(figures, indent=2))
