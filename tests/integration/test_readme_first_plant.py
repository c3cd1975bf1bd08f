"""README.md's "Your first plant", taken from the README itself and run as written.

Its ``plant.yaml`` passes ``fcmaster check``; the same file, with the serial port pointed at
simulated drives, free listen ports and a real mosquitto, runs, and the section's curl and
mbpoll commands do what the text says — including the stop of a drive at speed, which needs
the response timeout the README gives (mbpoll's own 1 s is shorter than the drive's
ramp-down, and the drive stops all the same).
"""

from __future__ import annotations

import asyncio
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.integration.daemon_harness import START_S, child, get_json, until
from tests.integration.mosquitto import Broker, Recorder
from tests.integration.ports import free_port

README = Path(__file__).parents[2] / "README.md"
TOKENS = {
    "FCM_VIEWER_TOKEN": "viewer-token-of-the-readme-0123",
    "FCM_OPERATOR_TOKEN": "operator-token-of-the-readme-0123",
}


def _section() -> str:
    text = README.read_text()
    start = text.index("\n## Your first plant\n")
    return text[start : text.index("\n## ", start + 1)]


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", _section(), re.DOTALL)


def _commands(program: str) -> list[str]:
    """The section's shell lines that run ``program``, continuation lines joined."""
    lines = "\n".join(_blocks("sh")).replace("\\\n", " ").splitlines()
    return [line for line in lines if line.startswith(f"{program} ")]


async def _shell(line: str, env: dict[str, str]) -> tuple[int, str]:
    """``line`` run by bash, as a reader pastes it; exit code and output."""
    process = await asyncio.create_subprocess_exec(
        "bash", "-c", line, env={**os.environ, **env},
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT,
    )  # fmt: skip
    async with asyncio.timeout(30):
        out, _ = await process.communicate()
    return process.returncode or 0, out.decode(errors="replace")


def test_the_readme_plant_passes_check(tmp_path: Path) -> None:
    (plant,) = _blocks("yaml")
    config = tmp_path / "plant.yaml"
    config.write_text(plant)
    done = subprocess.run(
        [sys.executable, "-m", "fcmaster", "check", "--config", str(config)],
        env={**os.environ, **TOKENS}, capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert "valid" in done.stdout
    assert "http, mqtt, modbus, metrics" in done.stdout  # every part the section explains


@pytest.mark.skipif(shutil.which("mbpoll") is None, reason="needs mbpoll")
@pytest.mark.skipif(shutil.which("curl") is None, reason="needs curl")
async def test_the_readme_curl_and_mbpoll_commands_work_as_written(tmp_path: Path) -> None:
    http_port, modbus_port = free_port(), free_port()
    (plant,) = _blocks("yaml")
    plant = plant.replace("port: /dev/ttyUSB0", "port: sim://line1")
    plant = plant.replace("127.0.0.1:8080", f"127.0.0.1:{http_port}")
    plant = plant.replace("127.0.0.1:5020", f"127.0.0.1:{modbus_port}")
    broker_directory = tmp_path / "mqtt"
    broker_directory.mkdir()
    broker = Broker(broker_directory)
    plant = plant.replace("mqtt://127.0.0.1:1883", broker.url)
    config = tmp_path / "plant.yaml"
    config.write_text(plant)

    def here(line: str) -> str:
        return line.replace("127.0.0.1:8080", f"127.0.0.1:{http_port}").replace(
            "-p 5020", f"-p {modbus_port}"
        )

    curls, mbpolls = _commands("curl"), _commands("mbpoll")
    assert len(curls) == 4
    assert [re.search(r"(\S+)\s+#", line) is not None for line in mbpolls] == [True] * 3
    read, start, stop = (here(line) for line in mbpolls)
    async with (
        broker,
        Recorder(broker, "fcmaster/#") as recorder,
        child("run", "--config", str(config), log=tmp_path / "run.log", env=TOKENS) as daemon,
        httpx.AsyncClient(base_url=f"http://127.0.0.1:{http_port}", timeout=10) as client,
    ):

        async def online() -> dict[str, Any] | None:
            pump: dict[str, Any] = await get_json(client, "/api/v1/drives/supply-pump-1")
            return pump if pump["online"] and "watchdog" in pump else None

        await until(online, "supply-pump-1 online and audited", alive=daemon, timeout_s=START_S)
        async with asyncio.timeout(START_S):  # and on MQTT, under the section's base topic
            await recorder.wait_json("fcmaster/line1/supply-pump-1/state", lambda s: s["online"])
        # curl: an anonymous read, /metrics with the viewer's token, a start and a stop
        answers = [await _shell(here(line), TOKENS) for line in curls]
        assert all(code == 0 for code, _ in answers), answers
        assert '"name": "supply-pump-1"' in answers[0][1]
        assert "fcmaster_drive_info{" in answers[1][1]
        assert [answer for _, answer in answers[2:]] == ['{"outcome": "done", "reason": ""}'] * 2

        code, output = await _shell(read, {})
        assert code == 0, output
        assert re.search(r"^\[0\]:\s+1$", output, re.MULTILINE), output  # online
        code, output = await _shell(start, {})
        assert code == 0, output

        async def at_speed() -> dict[str, Any] | None:
            pump: dict[str, Any] = await get_json(client, "/api/v1/drives/supply-pump-1")
            return pump if pump["running"] and pump["output_frequency_hz"] > 24.5 else None

        await until(at_speed, "supply-pump-1 at 25 Hz", alive=daemon)
        # the stop is answered once the drive stands, after its ramp: the README's -o allows it
        code, output = await _shell(stop, {})
        assert code == 0, output
        pump = await get_json(client, "/api/v1/drives/supply-pump-1")
        assert pump["running"] is False
        # what the README warns of: mbpoll's own timeout (1 s) gives up on the same stop
        code, output = await _shell(start, {})
        assert code == 0, output
        await until(at_speed, "supply-pump-1 at 25 Hz again", alive=daemon)
        code, output = await _shell(stop.replace(" -o 10", ""), {})
        assert code != 0
        assert "timed out" in output

        async def standing() -> dict[str, Any] | None:
            pump: dict[str, Any] = await get_json(client, "/api/v1/drives/supply-pump-1")
            return pump if not pump["running"] and pump["output_frequency_hz"] == 0 else None

        await until(standing, "supply-pump-1 stopped all the same", alive=daemon)  # as it says
