"""The poll gap on the lines a reload leaves alone: `fcmaster run` sent SIGHUP, watched on the wire.

Run: ``python benchmarks/reload_gap.py [--reloads 10] [--drives 8] [--baudrate 115200]
[--out PATH]`` (about a minute; results in ``benchmarks/results/reload_gap.json``).

Two lines of simulated FC drives run in this process, each on a pseudo-terminal that the
daemon (a subprocess, as deployed) opens as its serial port, so every telegram it sends is
decoded here with the time its last byte arrived. Each reload rewrites the config file so
that one drive is added to (then removed from) line ``north``, sends SIGHUP, and waits for
its log to say it was applied (``config.reloaded``; nothing asks the daemon meanwhile). For
the untouched line ``south`` and for drive 1 on ``north`` (a drive the reload keeps), the
gaps between consecutive polls of one drive are taken in the 2 s before the SIGHUP (the
normal interval: a poll round; and in the 1 s after, as the round may be longer then) and
from the SIGHUP until 1 s after the reload was applied.
Reported per reload and overall: the normal interval's median and maximum, the maximum
during the reload and its ratio to the normal maximum (target: no gap beyond one normal
interval), and how long the reload took. The control (``*_quiet``): the same measure on
windows as long, 4 s before each SIGHUP, where nothing happens, so that the machine's own
noise shows beside the reload's ratios.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import os
import signal
import socket
import statistics
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

import results_file

from fcmaster.clock import MonotonicClock
from fcmaster.protocol.danfoss_fc.framer import FcFramer
from fcmaster.protocol.danfoss_fc.telegram import decode_telegram
from fcmaster.protocol.framing import Frame
from fcmaster.sim.build import build_line
from fcmaster.sim.pty import PtyServer
from fcmaster.sim.settings import DriveSettings, LineSettings

CONFIG = """
buses:
  - name: north
    port: {north}
    baudrate: {baud}
    drives:
{north_drives}
  - name: south
    port: {south}
    baudrate: {baud}
    drives:
{south_drives}
http:
  listen: 127.0.0.1:{http}
  anonymous: viewer
logging: {{level: info, format: json}}
"""


class Wire:
    """Every telegram the daemon sent on one line: (when it arrived, address)."""

    def __init__(self) -> None:
        self.framer = FcFramer()
        self.telegrams: list[tuple[float, int]] = []

    def heard(self, data: bytes) -> None:
        self.framer.feed(data)
        while (piece := self.framer.next_frame()) is not None:
            if isinstance(piece, Frame):
                telegram = decode_telegram(piece.data, from_drive=False)
                self.telegrams.append((time.monotonic(), telegram.address))

    def gaps(self, start: float, end: float, address: int) -> list[float]:
        times = [t for t, a in self.telegrams if start <= t <= end and a == address]
        return [b - a for a, b in itertools.pairwise(times)]


def drives(addresses: range, prefix: str) -> str:
    return "\n".join(f"      - {{name: {prefix}-{a}, address: {a}}}" for a in addresses)


def _status(port: int) -> dict[str, Any]:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/v1/status", timeout=5) as answer:
        status: dict[str, Any] = json.load(answer)["config"]
    return status


def _reloads(log: Path) -> int:
    return log.read_text().count('"config.reloaded"')


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


async def _until(probe: Any, timeout_s: float = 60.0) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            found = await asyncio.to_thread(probe)
        except OSError:
            found = None
        if found:
            return found
        await asyncio.sleep(0.01)
    raise TimeoutError("the daemon did not get there in time")


def _window(wire: Wire, address: int, start: float, end: float) -> dict[str, float]:
    """The gaps from ``start`` to ``end`` beside those of the 2 s before and the 1 s after.

    (After a drive is added, a line's round is longer: the normal interval is the longer.)
    """
    normal = wire.gaps(start - 2.0, start, address) + wire.gaps(end, end + 1.0, address)
    during = wire.gaps(start - max(normal), end, address)
    return {
        "normal_median_ms": round(statistics.median(normal) * 1000, 2),
        "normal_max_ms": round(max(normal) * 1000, 2),
        "during_max_ms": round(max(during) * 1000, 2),
        "ratio": round(max(during) / max(normal), 2),
    }


async def main(args: argparse.Namespace) -> dict[str, Any]:
    clock = MonotonicClock()
    wires = {"north": Wire(), "south": Wire()}
    n = args.drives
    tmp = Path(tempfile.mkdtemp())
    http = _free_port()
    config = tmp / "plant.yaml"
    servers = []
    for name, first in (("north", 1), ("south", 1)):
        sim = [(a, DriveSettings()) for a in range(first, first + n + 1)]
        line = build_line(LineSettings(name=name, baudrate=args.baudrate), sim, clock=clock)
        pass_on, wire = line.write, wires[name]

        def record(data: bytes, wire: Wire = wire, pass_on: Any = pass_on) -> None:
            wire.heard(data)
            pass_on(data)

        line.write = record  # type: ignore[method-assign]
        servers.append(PtyServer(line, clock=clock, link=str(tmp / f"tty{name.upper()}")))

    def write(extra: bool) -> None:
        config.write_text(
            CONFIG.format(
                north=tmp / "ttyNORTH", south=tmp / "ttySOUTH", baud=args.baudrate, http=http,
                north_drives=drives(range(1, n + 1 + extra), "pump"),
                south_drives=drives(range(1, n + 1), "fan"),
            )
        )  # fmt: skip

    write(False)
    for server in servers:
        await server.__aenter__()
    daemon = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "fcmaster", "run", "--config", str(config),
        stdin=asyncio.subprocess.DEVNULL, stderr=(tmp / "run.log").open("wb"),
    )  # fmt: skip
    runs: list[dict[str, Any]] = []
    try:
        await _until(lambda: _status(http))
        await asyncio.sleep(7.0)  # every drive online, the rounds steady, a control window
        for k in range(args.reloads):
            write(k % 2 == 0)
            sighup = time.monotonic()
            daemon.send_signal(signal.SIGHUP)
            # Seen in its log, not asked over HTTP: the daemon does nothing for this.
            await _until(lambda k=k: _reloads(tmp / "run.log") > k)
            applied = time.monotonic()
            await asyncio.sleep(5.0)  # 1 s of polls after it; the next one's control and normal
            figures: dict[str, Any] = {"reload_s": round(applied - sighup, 4)}
            for name, address in (("south", 1), ("north", 1)):
                figures[name] = _window(wires[name], address, sighup, applied + 1.0)
                # the control: the same windows a reload earlier, with nothing happening
                sham = sighup - 4.0
                length = applied + 1.0 - sighup  # as long as the reload's window
                figures[f"{name}_quiet"] = _window(wires[name], address, sham, sham + length)
            runs.append(figures)
            print(json.dumps(figures), file=sys.stderr)
    finally:
        daemon.send_signal(signal.SIGTERM)
        await daemon.wait()
        for server in servers:
            await server.__aexit__(None, None, None)
    return {
        **results_file.provenance("reload_gap"),
        "settings": {"reloads": args.reloads, "drives": n, "baudrate": args.baudrate},
        "load_average": os.getloadavg(),
        "worst_ratio": {
            name: max(run[name]["ratio"] for run in runs)
            for name in ("south", "north", "south_quiet", "north_quiet")
        },
        "median_ratio": {
            name: statistics.median(run[name]["ratio"] for run in runs)
            for name in ("south", "north", "south_quiet", "north_quiet")
        },
        "median_reload_s": statistics.median(run["reload_s"] for run in runs),
        "runs": runs,
    }


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--reloads", type=int, default=10)
    parser.add_argument("--drives", type=int, default=8)
    parser.add_argument("--baudrate", type=int, default=115200)
    parser.add_argument(
        "--out", type=Path, default=Path(__file__).parent / "results" / "reload_gap.json"
    )
    arguments = parser.parse_args()
    results_file.run_and_write(main(arguments), arguments.out)
