"""A gateway killed while a Mitsubishi drive ramps down, restarted: nothing starts it again.

`fcmaster run` as a subprocess on a pseudo-terminal served by simulated Mitsubishi inverters
in this process; every run command an inverter takes is recorded with the time it came.
Two drives run at 40 Hz; one is stopped on a long deceleration (Pr.8 = 45 s) and the daemon
is killed (SIGKILL) a moment later. The daemon after it polls without commanding, so the
danger is the next command that changes only the reference: sent while the drive still
ramps down it must end without reaching the drive (``timeout``, HTTP 504, the reason
saying why), and sent once it stands it must not start it. The drive at speed takes its new
reference and keeps running.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
from pathlib import Path

import httpx

from fcmaster.clock import MonotonicClock
from fcmaster.protocol.mitsubishi.profile import RunCommand
from fcmaster.sim.build import build_line
from fcmaster.sim.mitsubishi.drive import MitsubishiSimDrive
from fcmaster.sim.pty import PtyServer
from fcmaster.sim.settings import DriveSettings, LineSettings
from tests.integration.daemon_harness import child, get_json, until
from tests.integration.ports import free_port

OPERATOR = "operator-token-0123456789abcdef"
CONFIG = """
buses:
  - name: line1
    port: {port}
    protocol: mitsubishi
    drives:
      - {{name: pump-1, address: 1, control: bus}}
      - {{name: pump-2, address: 2, control: bus}}
http:
  listen: 127.0.0.1:{http}
  tokens:
    - {{name: ops, role: operator, token: {token}}}
logging: {{format: json}}
"""
MOTION = RunCommand.STF | RunCommand.STR


async def test_a_restart_never_starts_a_mitsubishi_drive_that_was_stopping(tmp_path: Path) -> None:
    clock = MonotonicClock()
    settings = DriveSettings(parameters={"Pr.8": 45.0})
    line = build_line(
        LineSettings(protocol="mitsubishi", stopbits=2), [(1, settings), (2, settings)], clock=clock
    )
    drives = {d.address: d for d in line.drives if isinstance(d, MitsubishiSimDrive)}
    commands: list[tuple[float, int, int]] = []  # (time, address, run command bits)
    for address, drive in drives.items():
        take = drive.control.command

        def recorded(bits: int, now: float, take: object = take, address: int = address) -> None:
            commands.append((now, address, bits))
            take(bits, now)  # type: ignore[operator]

        drive.control.command = recorded  # type: ignore[method-assign]

    def output(address: int) -> float:
        drives[address].advance(clock.now())
        return abs(drives[address].motor.frequency_hz)

    http = free_port()
    link = tmp_path / "ttyLINE"
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(port=link, http=http, token=OPERATOR))
    headers = {"Authorization": f"Bearer {OPERATOR}"}
    base = f"http://127.0.0.1:{http}"

    async def online(client: httpx.AsyncClient) -> bool:
        return all(s["online"] for s in await get_json(client, "/api/v1/drives"))

    async with asyncio.timeout(180), PtyServer(line, clock=clock, link=str(link)):
        async with (
            child("run", "--config", str(config), log=tmp_path / "first.log") as first,
            httpx.AsyncClient(base_url=base, headers=headers, timeout=60) as client,
        ):
            await until(lambda: online(client), "every drive online", alive=first)
            for name in ("pump-1", "pump-2"):
                body = {"action": "start", "frequency_hz": 40}
                started = await client.post(f"/api/v1/drives/{name}/commands", json=body)
                assert started.json()["outcome"] == "done", started.text

            async def at_speed() -> bool:
                return all(abs(output(a) - 40.0) < 0.01 for a in drives)

            await until(at_speed, "both drives at 40 Hz", alive=first)

            async def stop() -> None:
                with contextlib.suppress(httpx.TransportError):  # the daemon is killed
                    await client.post("/api/v1/drives/pump-1/commands", json={"action": "stop"})

            stopping = asyncio.create_task(stop())

            async def ramping_down() -> bool:  # below SU's band (Pr.41: 10 % of 40 Hz)
                return output(1) < 35.0

            await until(ramping_down, "pump-1 ramping down", alive=first)
            first.process.send_signal(signal.SIGKILL)
            await first.process.wait()
            await stopping
        restarted_at = clock.now()

        async with (
            child("run", "--config", str(config), log=tmp_path / "second.log") as second,
            httpx.AsyncClient(base_url=base, headers=headers, timeout=60) as client,
        ):
            await until(lambda: online(client), "every drive online again", alive=second)
            slower = {"action": "set_reference", "frequency_hz": 20}
            during = await client.post("/api/v1/drives/pump-1/commands", json=slower)
            during_hz = output(1)

            async def standstill() -> bool:
                return output(1) == 0.0 and not drives[1].motor.output_on

            await until(standstill, "pump-1 at standstill", alive=second, timeout_s=60)
            after = await client.post("/api/v1/drives/pump-1/commands", json=slower)
            await asyncio.sleep(2.0)
            after_hz = output(1)
            other = await client.post(
                "/api/v1/drives/pump-2/commands",
                json={"action": "set_reference", "frequency_hz": 30},
            )

            async def at_30() -> bool:
                return abs(output(2) - 30.0) < 0.01

            await until(at_30, "pump-2 at its new reference", alive=second)

    assert during_hz > 0.0, "pump-1 stood before the reference was sent: nothing was tested"
    assert during.status_code == 504, during.text
    assert during.json()["outcome"] == "timeout"
    assert "output falling" in during.json()["reason"]
    assert after.json()["outcome"] == "done", after.text
    assert after_hz == 0.0
    assert other.json()["outcome"] == "done", other.text
    motion = [(a, bits) for at, a, bits in commands if at > restarted_at and bits & MOTION]
    assert motion == [(2, int(RunCommand.STF))]  # pump-2's reference; nothing to pump-1
