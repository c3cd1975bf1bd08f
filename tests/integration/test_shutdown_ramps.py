"""SIGTERM while stops wait for long ramps: every client gets its outcome, never a 500.

`fcmaster run` as a subprocess on a pseudo-terminal served by simulated FC drives in this
process. Four drives run at 40 Hz with a 60 s deceleration (3-42), so a stop takes 48 s to
show; eight HTTP clients keep sending stops, each waiting for its result, and the daemon is
sent SIGTERM. Its shutdown waits for the stops up to ``shutdown_timeout_s`` and then ends
what is still open: every request answered is JSON with an outcome, none a 500, and the
daemon logs no error or traceback.
"""

from __future__ import annotations

import asyncio
import itertools
import signal
import time
from pathlib import Path

import httpx

from fcmaster.clock import MonotonicClock
from fcmaster.sim.build import build_line
from fcmaster.sim.danfoss_fc.drive import FcSimDrive
from fcmaster.sim.pty import PtyServer
from fcmaster.sim.settings import DriveSettings, LineSettings
from tests.integration.daemon_harness import EXIT_S, child, get_json, until
from tests.integration.ports import free_port

OPERATOR = "operator-token-0123456789abcdef"
ADDRESSES = (1, 2, 3, 4)
BOUND_S = 6
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
shutdown_timeout_s: {bound}
logging: {{format: json}}
"""


async def test_stops_waiting_for_long_ramps_at_sigterm_each_get_an_outcome(tmp_path: Path) -> None:
    clock = MonotonicClock()
    settings = DriveSettings(parameters={"3-42": 60.0})
    line = build_line(LineSettings(baudrate=19200), [(a, settings) for a in ADDRESSES], clock=clock)
    drives = {d.address: d for d in line.drives if isinstance(d, FcSimDrive)}
    http = free_port()
    link = tmp_path / "ttyLINE"
    rows = "\n".join(f"      - {{name: pump-{a}, address: {a}, control: bus}}" for a in ADDRESSES)
    config = tmp_path / "plant.yaml"
    config.write_text(
        CONFIG.format(port=link, drives=rows, http=http, token=OPERATOR, bound=BOUND_S)
    )
    headers = {"Authorization": f"Bearer {OPERATOR}"}
    answers: list[httpx.Response] = []

    async with (
        asyncio.timeout(120),
        PtyServer(line, clock=clock, link=str(link)),
        child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
        httpx.AsyncClient(
            base_url=f"http://127.0.0.1:{http}", headers=headers, timeout=60
        ) as client,
    ):

        async def online() -> bool:
            return all(s["online"] for s in await get_json(client, "/api/v1/drives"))

        await until(online, "every drive online", alive=daemon)
        for a in ADDRESSES:
            body = {"action": "start", "frequency_hz": 40}
            started = await client.post(f"/api/v1/drives/pump-{a}/commands", json=body)
            assert started.json()["outcome"] == "done", started.text

        async def at_speed() -> bool:
            for drive in drives.values():
                drive.advance(clock.now())
            return all(abs(d.motor.frequency_hz - 40.0) < 0.01 for d in drives.values())

        await until(at_speed, "every drive at 40 Hz", alive=daemon)

        async def sender(n: int) -> None:
            for i in itertools.count():
                if daemon.process.returncode is not None:
                    return
                drive = f"pump-{1 + (i + n) % len(ADDRESSES)}"
                try:
                    response = await client.post(
                        f"/api/v1/drives/{drive}/commands", json={"action": "stop"}
                    )
                except httpx.TransportError:  # the listener closed: nothing was accepted
                    await asyncio.sleep(0.05)
                    continue
                answers.append(response)

        senders = [asyncio.create_task(sender(n)) for n in range(8)]
        await asyncio.sleep(1.0)  # every sender has a stop waiting for its drive's ramp
        signalled = time.monotonic()
        daemon.process.send_signal(signal.SIGTERM)
        code = await asyncio.wait_for(daemon.process.wait(), BOUND_S + EXIT_S)
        took = time.monotonic() - signalled
        await asyncio.gather(*senders)
        assert code == 0, daemon.tail()

    assert len(answers) >= 8
    bad = [(r.status_code, r.text) for r in answers if r.status_code not in (200, 409, 503, 504)]
    assert bad == [], f"{len(bad)} of {len(answers)} answers were not outcomes"
    for response in answers:
        assert response.headers["content-type"] == "application/json", response.text
        assert "outcome" in response.json()
    events = daemon.log_events()  # every line JSON: none from the server's own cancellations
    assert not [e for e in events if e.get("level") in ("error", "critical") or "exception" in e]
    assert took < BOUND_S + EXIT_S
