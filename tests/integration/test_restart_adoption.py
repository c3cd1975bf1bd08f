"""A gateway killed while its drives ramp down, and restarted: no stopping motor starts again.

`fcmaster run` as a subprocess on a pseudo-terminal served by simulated FC drives in this
process, so every telegram each daemon sends is decoded here together with what the drive
was doing when it arrived. Four drives run at 40 Hz; two are stopped on a long ramp
(3-42 = 45 s) and the daemon is killed (SIGKILL: no shutdown of any kind) a moment later.
A second daemon adopts the line while they still ramp down: it must never put a run word
to them on the wire, and they reach standstill; the two at speed must never get a stop word
and keep their speed.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
from pathlib import Path
from typing import Any

import httpx

from fcmaster.clock import MonotonicClock
from fcmaster.protocol.danfoss_fc.framer import FcFramer
from fcmaster.protocol.danfoss_fc.profile import ControlWord
from fcmaster.protocol.danfoss_fc.telegram import decode_telegram
from fcmaster.protocol.framing import Frame
from fcmaster.sim.build import build_line
from fcmaster.sim.danfoss_fc.drive import FcSimDrive
from fcmaster.sim.pty import PtyServer
from fcmaster.sim.settings import DriveSettings, LineSettings
from tests.integration.daemon_harness import child, get_json, until
from tests.integration.ports import free_port

OPERATOR = "operator-token-0123456789abcdef"
ADDRESSES = (1, 2, 3, 4)
STOPPED = (1, 2)
RUNNING = (3, 4)
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
logging: {{format: json}}
"""


class Wire:
    """Every valid control word the daemons sent: (address, word, the drive's output then)."""

    def __init__(self, drives: dict[int, FcSimDrive], clock: MonotonicClock) -> None:
        self.framer = FcFramer()
        self.drives = drives
        self.clock = clock
        self.words: list[tuple[int, int, float]] = []

    def heard(self, data: bytes) -> None:
        self.framer.feed(data)
        while (piece := self.framer.next_frame()) is not None:
            if not isinstance(piece, Frame):
                continue
            telegram = decode_telegram(piece.data, from_drive=False)
            drive = self.drives.get(telegram.address)
            if drive is not None and telegram.pcd1 & ControlWord.DATA_VALID:
                drive.advance(self.clock.now())
                self.words.append((telegram.address, telegram.pcd1, drive.motor.frequency_hz))


def runs(word: int) -> bool:
    """Whether a valid control word asks the motor to run (start, and no stop of any kind)."""
    needed = (
        ControlWord.START | ControlWord.NO_COAST | ControlWord.NO_QUICK_STOP
    ) | ControlWord.NO_DC_BRAKE
    return word & needed == needed


def output(drive: FcSimDrive, clock: MonotonicClock) -> float:
    drive.advance(clock.now())
    return drive.motor.frequency_hz


async def test_a_restart_never_starts_a_drive_ramping_down_after_a_stop(tmp_path: Path) -> None:
    clock = MonotonicClock()
    settings = DriveSettings(parameters={"3-42": 45.0})  # 45 s from 50 Hz to 0
    line = build_line(LineSettings(baudrate=19200), [(a, settings) for a in ADDRESSES], clock=clock)
    drives = {d.address: d for d in line.drives if isinstance(d, FcSimDrive)}
    wire = Wire(drives, clock)
    pass_on = line.write

    def record(data: bytes) -> None:
        wire.heard(data)
        pass_on(data)

    line.write = record  # type: ignore[method-assign]
    http = free_port()
    link = tmp_path / "ttyLINE"
    rows = "\n".join(f"      - {{name: pump-{a}, address: {a}, control: bus}}" for a in ADDRESSES)
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(port=link, drives=rows, http=http, token=OPERATOR))
    headers = {"Authorization": f"Bearer {OPERATOR}"}
    base = f"http://127.0.0.1:{http}"

    async def all_online(client: httpx.AsyncClient) -> bool:
        states = await get_json(client, "/api/v1/drives")
        return len(states) == len(ADDRESSES) and all(s["online"] for s in states)

    async with asyncio.timeout(180), PtyServer(line, clock=clock, link=str(link)):
        async with (
            child("run", "--config", str(config), log=tmp_path / "first.log") as first,
            httpx.AsyncClient(base_url=base, headers=headers, timeout=60) as client,
        ):
            await until(lambda: all_online(client), "every drive online", alive=first)
            for a in ADDRESSES:
                body = {"action": "start", "frequency_hz": 40}
                started = await client.post(f"/api/v1/drives/pump-{a}/commands", json=body)
                assert started.json()["outcome"] == "done", started.text

            async def at_speed() -> bool:
                return all(abs(output(drives[a], clock) - 40.0) < 0.01 for a in ADDRESSES)

            await until(at_speed, "every drive at 40 Hz", alive=first)

            async def stop(a: int) -> Any:
                with contextlib.suppress(httpx.TransportError):  # the daemon is killed
                    await client.post(f"/api/v1/drives/pump-{a}/commands", json={"action": "stop"})

            stops = [asyncio.create_task(stop(a)) for a in STOPPED]

            async def ramping_down() -> bool:
                return all(output(drives[a], clock) < 38.0 for a in STOPPED)

            await until(ramping_down, "the stopped drives ramping down", alive=first)
            first.process.send_signal(signal.SIGKILL)
            await first.process.wait()
            await asyncio.gather(*stops)
        killed_at = {a: output(drives[a], clock) for a in ADDRESSES}
        heard_before = len(wire.words)

        async with (
            child("run", "--config", str(config), log=tmp_path / "second.log") as second,
            httpx.AsyncClient(base_url=base, headers=headers, timeout=60) as client,
        ):
            await until(lambda: all_online(client), "every drive online again", alive=second)

            async def standstill() -> bool:
                return all(
                    output(drives[a], clock) == 0.0 and not drives[a].motor.output_on
                    for a in STOPPED
                )

            await until(standstill, "the stopped drives at standstill", alive=second, timeout_s=60)
            await asyncio.sleep(1.0)  # and a few more polls
            states = {s["name"]: s for s in await get_json(client, "/api/v1/drives")}

    after = wire.words[heard_before:]
    story = f"killed at {killed_at}; after the restart: " + ", ".join(
        f"{a}:{w:#06x}@{hz:.1f}Hz" for a, w, hz in after[:40]
    )
    for a in STOPPED:
        words = [(w, hz) for address, w, hz in after if address == a]
        assert words, story
        assert words[0][1] > 0.0, f"drive {a} stood before the restart commanded it: {story}"
        assert [hex(w) for w, _ in words if runs(w)] == [], story
        assert not states[f"pump-{a}"]["running"]
    for a in RUNNING:
        told = [w for address, w, _ in after if address == a]
        assert told, story
        assert [hex(w) for w in told if not runs(w)] == [], story
        assert abs(output(drives[a], clock) - 40.0) < 0.01
        assert states[f"pump-{a}"]["running"]
