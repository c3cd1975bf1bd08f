"""Running the commissioning commands the way a technician does: one `python -m fcmaster`
process per command, against simulated drives served on a pseudo-terminal by the test's
event loop."""

from __future__ import annotations

import asyncio
import json
import sys
from collections.abc import AsyncIterator, Iterable, Sequence
from contextlib import asynccontextmanager
from pathlib import Path

from fcmaster.clock import MonotonicClock
from fcmaster.sim import DriveSettings, LineSettings, PtyServer, build_line
from tests.integration.daemon_harness import child

LIMIT_S = 60.0  # one test's whole budget: a cold interpreter per command on a busy machine


@asynccontextmanager
async def served(
    line: LineSettings, drives: Iterable[tuple[int, DriveSettings]]
) -> AsyncIterator[PtyServer]:
    """``drives`` on a simulated ``line``, served on a pty until the block ends (bounded)."""
    clock = MonotonicClock()
    built = build_line(line, drives, clock=clock)
    async with asyncio.timeout(LIMIT_S), PtyServer(built, clock=clock) as server:
        yield server


async def fcmaster(server: PtyServer, protocol: str, *args: str) -> tuple[int, str, str]:
    """``fcmaster args[0] --port PTY --protocol protocol args[1:]``: exit code, out, err."""
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "fcmaster", args[0], "--port", server.device,
        "--protocol", protocol, *args[1:],
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    out, err = await process.communicate()
    assert process.returncode is not None
    return process.returncode, out.decode(), err.decode()


async def scan_a_served_sim(
    tmp: Path, sim_args: Sequence[str], scan_args: Sequence[str]
) -> tuple[str, list[int]]:
    """``fcmaster sim SIM_ARGS`` in its own process, and ``fcmaster scan`` on its pty.

    The bus name the simulator printed, and the addresses the scan found (its stderr is
    logged to ``tmp``, so a chatty simulator never stalls on a full pipe).
    """
    async with asyncio.timeout(LIMIT_S), child("sim", *sim_args, log=tmp / "sim.log") as sim:
        name, path = (await sim.readline()).split()
        scan = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "fcmaster", "scan", "--port", path, *scan_args, "--json",
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        )  # fmt: skip
        out, err = await scan.communicate()
    assert scan.returncode == 0, err.decode()
    return name, [entry["address"] for entry in json.loads(out)]
