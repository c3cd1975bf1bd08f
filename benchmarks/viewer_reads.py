"""What many viewers reading parameters cost the poll.

Run: ``python benchmarks/viewer_reads.py [--readers 50] [--seconds 10]``

The demo (`fcmaster run`, no config: two simulated lines, anonymous loopback reads) runs
as a subprocess. For ``--seconds`` it is left alone, then ``--readers`` anonymous clients
read ``16-13`` of one drive on line1 as fast as they are answered, for as long. Reported
for each phase: the requests per second to cooling-fan-2 (a monitor drive on line1, whose
poll is what viewers' reads take time from) and the reads per second the readers got.
Viewer reads are spaced out per line (``fcmaster/adapters/readlimit.py``), so the poll
rate with readers stays within a couple of transactions of the one without.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import sys
import time
from typing import Any

import httpx

DRIVE = "cooling-fan-2"


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


async def _polls(client: httpx.AsyncClient) -> int:
    buses = (await client.get("/api/v1/buses")).json()
    line1 = next(b for b in buses if b["name"] == "line1")
    return int(line1["stats"]["drives"][DRIVE]["requests"])


async def main(readers: int, seconds: float) -> dict[str, Any]:
    port = _free_port()
    daemon = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "fcmaster", "run", "--http-listen", f"127.0.0.1:{port}",
        stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL,
    )  # fmt: skip
    try:
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}", timeout=60) as client:
            for _ in range(300):
                try:
                    if all(d["online"] for d in (await client.get("/api/v1/drives")).json()):
                        break
                except httpx.HTTPError:
                    pass
                await asyncio.sleep(0.1)
            before = await _polls(client)
            await asyncio.sleep(seconds)
            alone = (await _polls(client) - before) / seconds

            reads = 0
            statuses: dict[int, int] = {}
            stop_at = time.monotonic() + seconds

            async def reader() -> None:
                nonlocal reads
                while time.monotonic() < stop_at:
                    response = await client.get("/api/v1/drives/supply-pump-1/parameters/16-13")
                    statuses[response.status_code] = statuses.get(response.status_code, 0) + 1
                    if response.status_code == 200:
                        reads += 1
                    else:
                        await asyncio.sleep(1.0)

            before = await _polls(client)
            started = time.monotonic()
            await asyncio.gather(*(reader() for _ in range(readers)))
            took = time.monotonic() - started
            with_readers = (await _polls(client) - before) / took
    finally:
        daemon.terminate()
        await daemon.wait()
    return {
        "readers": readers,
        "polls_per_s_alone": round(alone, 1),
        "polls_per_s_with_readers": round(with_readers, 1),
        "viewer_reads_per_s": round(reads / took, 1),
        "answers": statuses,
        "loadavg": os.getloadavg(),
    }


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--readers", type=int, default=50)
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    print(json.dumps(asyncio.run(main(args.readers, args.seconds)), indent=2))
