"""How long SIGTERM takes with ``on_shutdown: stop`` as the drives' deceleration grows.

Run: ``python benchmarks/shutdown_ramps.py [--output PATH]`` (about 2.5 minutes).

For each deceleration time (FC 3-42: 3, 10, 30 and 100 s from 50 Hz to 0), four simulated
FC drives are served on a pty in this process and ``fcmaster run`` (a subprocess, the
default ``shutdown_timeout_s`` of 60 s) commands them over it. Every drive is started at
40 Hz through the HTTP API; once all run at speed the daemon gets SIGTERM. Figures: the
seconds from the signal to the daemon's exit, the drives' output when it exited (0: it
waited for their stops), and the warnings it logged. A stop from 40 Hz takes 0.8 of the
deceleration time; each stop's deadline is that time plus 2 s, at least 5 s.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import socket
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import results_file

from fcmaster.clock import MonotonicClock
from fcmaster.sim import DriveSettings, FcSimDrive, LineSettings, PtyServer, build_line

ADDRESSES = (1, 2, 3, 4)
RAMPS_S = (3.0, 10.0, 30.0, 100.0)
TOKEN = "operator-token-0123456789abcdef"
CONFIG = """
buses:
  - name: line1
    port: {port}
    baudrate: 19200
    drives:
{drives}
http:
  listen: 127.0.0.1:{http}
  tokens:
    - {{name: ops, role: operator, token: {token}}}
on_shutdown: stop
logging: {{format: json}}
"""


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


async def _until(check: Any, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            if await check():
                return
        except httpx.TransportError:
            pass
        if time.monotonic() > deadline:
            raise TimeoutError("the daemon did not get there in time")
        await asyncio.sleep(0.1)


async def run_case(ramp_s: float, workdir: Path) -> dict[str, Any]:
    clock = MonotonicClock()
    settings = DriveSettings(parameters={"3-42": ramp_s})
    line = build_line(LineSettings(baudrate=19200), [(a, settings) for a in ADDRESSES], clock=clock)
    drives = [d for d in line.drives if isinstance(d, FcSimDrive)]
    http = _free_port()
    link = workdir / f"tty{int(ramp_s)}"
    rows = "\n".join(f"      - {{name: pump-{a}, address: {a}, control: bus}}" for a in ADDRESSES)
    config = workdir / f"plant{int(ramp_s)}.yaml"
    config.write_text(CONFIG.format(port=link, drives=rows, http=http, token=TOKEN))
    log = workdir / f"run{int(ramp_s)}.log"

    def outputs() -> list[float]:
        for drive in drives:
            drive.advance(clock.now())
        return [round(d.motor.frequency_hz, 2) for d in drives]

    async with PtyServer(line, clock=clock, link=str(link)):
        with log.open("wb") as stderr:
            daemon = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "fcmaster", "run", "--config", str(config),
                stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.DEVNULL,
                stderr=stderr,
            )  # fmt: skip
        headers = {"Authorization": f"Bearer {TOKEN}"}
        try:
            async with httpx.AsyncClient(
                base_url=f"http://127.0.0.1:{http}", headers=headers, timeout=30
            ) as client:

                async def online() -> bool:
                    states = (await client.get("/api/v1/drives")).json()
                    return all(s["online"] for s in states)

                await _until(online)
                for a in ADDRESSES:
                    body = {"action": "start", "frequency_hz": 40}
                    await client.post(f"/api/v1/drives/pump-{a}/commands", json=body)

                async def at_speed() -> bool:
                    return all(abs(hz - 40.0) < 0.01 for hz in outputs())

                await _until(at_speed)
            signalled = time.monotonic()
            daemon.send_signal(signal.SIGTERM)
            code = await daemon.wait()
            took = time.monotonic() - signalled
            at_exit = outputs()
        finally:
            if daemon.returncode is None:
                daemon.kill()
                await daemon.wait()
    events = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
    warnings = [e["event"] for e in events if e.get("level") in ("warning", "error")]
    return {
        "ramp_down_s": ramp_s,
        "stop_from_40_hz_s": 0.8 * ramp_s,
        "exit_code": code,
        "sigterm_to_exit_s": round(took, 2),
        "outputs_at_exit_hz": at_exit,
        "warnings": warnings,
    }


async def main_async() -> list[dict[str, Any]]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for ramp_s in RAMPS_S:
            row = await run_case(ramp_s, Path(tmp))
            print(
                f"3-42 {ramp_s:>5g} s  exit after {row['sigterm_to_exit_s']:>6.2f} s"
                f"  outputs {row['outputs_at_exit_hz']}  {row['warnings']}",
                flush=True,
            )
            rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--output", type=Path, default=Path(__file__).parent / "results" / "shutdown_ramps.json"
    )
    args = parser.parse_args(argv)
    load_before = os.getloadavg()
    rows = asyncio.run(main_async())
    results = {
        **results_file.provenance("shutdown_ramps"),
        "loadavg_before": load_before,
        "loadavg_after": os.getloadavg(),
        "cases": rows,
    }
    results_file.write(args.output, results)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
