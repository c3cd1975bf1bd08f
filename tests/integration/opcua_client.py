"""node-opcua (tests/node/opcua/client.js) as the OPC UA client of the integration tests.

A client that is not asyncua, so the server is judged by another stack's reading of the
standard. Each plan runs one ``node`` process and returns the JSON it printed last (the
library logs to stdout too). A missing node or ``node_modules`` fails the test: .ci/run
installs them.
"""

from __future__ import annotations

import asyncio
import json
import shutil
from pathlib import Path
from typing import Any

import pytest

CLIENT = Path(__file__).parents[1] / "node" / "opcua"
RUN_S = 60.0  # node starting and making its certificate on a busy 2-core machine


def node_binary() -> str:
    """The node executable; fails the test when node or the client's packages are missing."""
    found = shutil.which("node")
    if found is None or not (CLIENT / "node_modules" / "node-opcua-client").is_dir():
        pytest.fail(
            "node and the OPC UA test client are needed: "
            "(cd tests/node/opcua && npm ci) — .ci/run does it"
        )
    return found


def _write(file: Path, text: str) -> None:
    file.parent.mkdir(parents=True, exist_ok=True)
    file.write_text(text)


async def run_plan(plan: dict[str, Any], folder: Path) -> dict[str, Any]:
    """Run ``plan`` (see client.js) and return what the client reports."""
    return await finished(await start_plan(plan, folder))


async def start_plan(plan: dict[str, Any], folder: Path) -> asyncio.subprocess.Process:
    """Start a client on ``plan``; :func:`finished` waits for its report."""
    file = folder / "plan.json"
    await asyncio.to_thread(_write, file, json.dumps(plan))
    return await asyncio.create_subprocess_exec(
        node_binary(), str(CLIENT / "client.js"), str(file),
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, cwd=CLIENT,
    )  # fmt: skip


async def subscribed(process: asyncio.subprocess.Process) -> float:
    """Wait for a ``count`` step's client to say it is subscribed; the seconds it took."""
    assert process.stderr is not None
    async with asyncio.timeout(RUN_S):
        while line := (await process.stderr.readline()).decode():
            if line.startswith("subscribed "):
                return int(line.split()[1]) / 1000
    raise AssertionError(f"the OPC UA client ended unsubscribed: {await finished(process)}")


async def finished(process: asyncio.subprocess.Process) -> dict[str, Any]:
    """What a started client reported, once it has ended."""
    out, err = await asyncio.wait_for(process.communicate(), RUN_S)
    lines = [line for line in out.decode().splitlines() if line.startswith("{")]
    assert lines, f"the OPC UA client printed no result:\n{out.decode()}\n{err.decode()}"
    result: dict[str, Any] = json.loads(lines[-1])
    return result
