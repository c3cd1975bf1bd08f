"""The Docker image's HEALTHCHECK, run as Docker runs it, against a real daemon.

There may be no Docker where the tests run, so the command is taken from the Dockerfile and
run here the way Docker would run it in the container (exec form, the image's environment):
it passes while ``fcmaster run`` serves HTTP — with tokens configured and a proxy in the
environment — and fails once the daemon is gone. The build arguments and the ports are read
from the Dockerfile too.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import httpx

from tests.integration.daemon_harness import EXIT_S, START_S, child
from tests.integration.ports import free_port

DOCKERFILE = Path(__file__).parents[2] / "Dockerfile"
TOKEN = "viewer-token-for-the-healthcheck-0123"
CONFIG = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    drives:
      - {{name: pump-1, address: 1}}
http:
  listen: 127.0.0.1:{port}
  tokens:
    - {{name: scada, role: viewer, token: "{token}"}}
"""


def _instructions() -> list[str]:
    """The Dockerfile's instructions, continuation lines joined, comments left out."""
    lines = [line for line in DOCKERFILE.read_text().splitlines() if not line.startswith("#")]
    return [i.strip() for i in re.sub(r"\\\n\s*", " ", "\n".join(lines)).splitlines() if i.strip()]


def _healthcheck() -> tuple[list[str], str]:
    """The HEALTHCHECK's command (exec form) and the image's FCMASTER_HEALTH_URL."""
    (check,) = [i for i in _instructions() if i.startswith("HEALTHCHECK ")]
    argv = json.loads(check.split(" CMD ", 1)[1])
    (url,) = re.findall(r"^ENV FCMASTER_HEALTH_URL=(\S+)$", DOCKERFILE.read_text(), re.M)
    return argv, url


async def _run_healthcheck(argv: list[str], url: str) -> int:
    """Its exit status, run with the image's environment: python3 on PATH, a proxy set."""
    env = {
        **os.environ,
        "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}",
        "FCMASTER_HEALTH_URL": url,
        "HTTP_PROXY": "http://127.0.0.1:9",  # nothing listens there: it must be passed by
        "http_proxy": "http://127.0.0.1:9",
    }
    process = await asyncio.create_subprocess_exec(
        *argv, env=env, stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL
    )
    async with asyncio.timeout(10):  # the HEALTHCHECK's own --timeout is 5 s
        return await process.wait()


def test_the_image_exposes_modbus_and_takes_an_index_and_a_ca_at_build() -> None:
    instructions = _instructions()
    (expose,) = [i for i in instructions if i.startswith("EXPOSE ")]
    assert expose.split()[1:] == ["8080", "5020"]
    froms = [n for n, i in enumerate(instructions) if i.startswith("FROM ")]
    build = instructions[froms[0] : froms[1]]  # the stage that runs pip
    for arg in ("PIP_INDEX_URL", "PIP_EXTRA_INDEX_URL", "PIP_TRUSTED_HOST", "CA_BUNDLE"):
        assert f"ARG {arg}" in build
    _, url = _healthcheck()
    assert url == "http://127.0.0.1:8080/"
    for run in (i for i in instructions if i.startswith("RUN ")):  # each a valid sh script
        assert subprocess.run(["sh", "-n", "-c", run[4:]], check=False).returncode == 0, run


async def test_the_healthcheck_passes_while_the_daemon_serves_and_fails_when_it_is_gone(
    tmp_path: Path,
) -> None:
    argv, _ = _healthcheck()
    assert argv[0] == "python3"  # the image has no curl
    port = free_port()
    url = f"http://127.0.0.1:{port}/"
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(port=port, token=TOKEN))
    assert await _run_healthcheck(argv, url) != 0  # nothing listens yet
    async with child("run", "--config", str(config), log=tmp_path / "run.log") as daemon:
        async with asyncio.timeout(START_S):
            while await _run_healthcheck(argv, url) != 0:
                assert daemon.running, daemon.tail()
                await asyncio.sleep(0.2)
        async with httpx.AsyncClient() as client:  # tokens are on: reads need one
            assert (await client.get(f"{url}api/v1/drives")).status_code == 401
        daemon.process.send_signal(signal.SIGTERM)
        async with asyncio.timeout(EXIT_S):
            assert await daemon.process.wait() == 0
    assert await _run_healthcheck(argv, url) != 0
