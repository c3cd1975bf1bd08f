"""One program per port: a second opener of a busy pty is told who has it and exits 1.

The daemon runs as a subprocess on a pseudo-terminal served by the simulator in this
process. While it polls, a commissioning command and a second daemon try the same port:
both exit 1 naming the daemon's PID, and the daemon's line counts no timeout, checksum
error or noise meanwhile — the second opener never touched the line.
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import httpx
import pytest

from fcmaster.clock import MonotonicClock
from fcmaster.errors import PortInUse
from fcmaster.sim.build import build_line
from fcmaster.sim.pty import PtyServer
from fcmaster.sim.settings import DriveSettings, LineSettings
from fcmaster.transport.serial import SerialTransport
from tests.integration.daemon_harness import START_S, child, get_json, until
from tests.integration.ports import free_port

CONFIG = """
buses:
  - name: line1
    port: {port}
    baudrate: 38400
    drives:
      - {{name: pump-1, address: 1}}
      - {{name: pump-2, address: 2}}
http:
  listen: 127.0.0.1:{http}
  anonymous: viewer
  tokens:
    - {{name: scada, role: viewer, token: viewer-token-0123456789}}
logging: {{format: json}}
"""
ERRORS = ("timeouts", "checksum_errors", "malformed", "unexpected", "noise_bytes", "late_bytes")


async def _exits_1_naming(args: list[str], log: Path, port: Path, pid: int) -> str:
    async with child(*args, log=log) as tool:
        code = await asyncio.wait_for(tool.process.wait(), START_S)
    said = tool.tail(40)
    assert code == 1, said
    assert f"port {port} is in use by PID {pid} (" in said, said
    return said


async def test_a_second_opener_of_a_busy_port_exits_1_and_the_line_loses_nothing(
    tmp_path: Path,
) -> None:
    clock = MonotonicClock()
    line = build_line(
        LineSettings(baudrate=38400),
        [(a, DriveSettings(response_delay_s=0.005)) for a in (1, 2)],
        clock=clock,
    )
    link = tmp_path / "ttyBUSY"
    http = free_port()
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(port=link, http=http))
    async with (
        asyncio.timeout(120),
        PtyServer(line, clock=clock, link=str(link)),
        child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
        httpx.AsyncClient(base_url=f"http://127.0.0.1:{http}") as client,
    ):

        async def polled() -> dict[str, Any] | None:
            (bus,) = await get_json(client, "/api/v1/buses")
            stats: dict[str, Any] = bus["stats"]
            return stats if bus["up"] and stats["replies"] > 20 else None

        before = await until(polled, "the line polled", alive=daemon, timeout_s=60)
        pid = daemon.process.pid
        status = ["status", "--port", str(link), "--baudrate", "38400", "--address", "1"]
        await _exits_1_naming(status, tmp_path / "status.log", link, pid)
        other = tmp_path / "other.yaml"
        other.write_text(CONFIG.format(port=link, http=free_port()))
        said = await _exits_1_naming(
            ["run", "--config", str(other)], tmp_path / "other.log", link, pid
        )
        assert "fcmaster run" in said

        (bus,) = await get_json(client, "/api/v1/buses")
        after = bus["stats"]
        daemon.check_alive()
        assert bus["up"] is True
        assert after["replies"] > before["replies"]  # still polling, all along
        assert {k: after[k] for k in ERRORS} == {k: before[k] for k in ERRORS}


async def test_in_process_the_open_fails_as_port_in_use_and_the_port_is_free_after(
    tmp_path: Path,
) -> None:
    clock = MonotonicClock()
    line = build_line(LineSettings(baudrate=38400), [(1, DriveSettings())], clock=clock)
    async with PtyServer(line, clock=clock, link=str(tmp_path / "tty")) as server:
        first = SerialTransport(server.device, baudrate=38400)
        second = SerialTransport(server.device, baudrate=38400)
        await first.open()
        try:
            with pytest.raises(PortInUse) as caught:
                await second.open()
        finally:
            await first.close()
        # held by this very process: /proc/locks names no other PID
        assert str(caught.value) == f"port {server.device} is in use by another program"
        await second.open()  # the lock went with the first
        await second.close()
