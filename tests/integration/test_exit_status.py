"""`fcmaster run`'s exit status and signals, as systemd and docker see them.

The daemon runs against `fcmaster sim` on a pty. A shutdown stop that cannot reach its drive
(the line's adapter is gone) leaves a motor that may be turning: the daemon says so with
exit status 3, not 0. SIGHUP asks for a reload; it never ends the daemon.
"""

from __future__ import annotations

import signal
from pathlib import Path

import httpx

from tests.integration.daemon_harness import Child, by_name, child, get_json, until
from tests.integration.ports import free_port

CONFIG = """
buses:
  - name: north
    port: {north}
    baudrate: 38400
    drives:
      - {{name: pump-1, address: 1, control: bus}}
    simulation:
      drives:
        1: {{running_hz: 30}}
http:
  listen: 127.0.0.1:{port}
  anonymous: viewer
on_shutdown: stop
"""


def _plant(tmp_path: Path) -> tuple[Path, int]:
    port = free_port()
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(north=tmp_path / "ttyNORTH", port=port))
    return config, port


async def _online(daemon: Child, port: int) -> None:
    async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}", timeout=10) as client:

        async def online() -> bool:
            drives = by_name(await get_json(client, "/api/v1/drives"))
            return bool(drives["pump-1"]["online"])

        await until(online, "pump-1 online", alive=daemon)


async def test_a_shutdown_stop_that_cannot_reach_its_drive_ends_with_exit_status_3(
    tmp_path: Path,
) -> None:
    config, port = _plant(tmp_path)
    async with child("run", "--config", str(config), log=tmp_path / "run.log") as daemon:
        async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
            await sim.readline()
            await _online(daemon, port)
        # The simulator is gone with its pty: the stop has no line to go out on.
        code, _ = await daemon.stop(signal.SIGTERM)
    assert code == 3, daemon.tail()
    failed = [e for e in daemon.log_events() if e["event"] == "service.shutdown_stop_failed"]
    assert [e["drive"] for e in failed] == ["pump-1"]


async def test_sighup_leaves_the_daemon_running_and_a_stop_that_reached_its_drive_exits_0(
    tmp_path: Path,
) -> None:
    config, port = _plant(tmp_path)
    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        await sim.readline()
        async with child("run", "--config", str(config), log=tmp_path / "run.log") as daemon:
            await _online(daemon, port)
            daemon.process.send_signal(signal.SIGHUP)
            await until(
                lambda: _logged(daemon, "config.reload_requested"), "the reload", alive=daemon
            )
            await _online(daemon, port)  # still serving after the SIGHUP
            code, _ = await daemon.stop(signal.SIGTERM)
    assert code == 0, daemon.tail()
    events = [e["event"] for e in daemon.log_events()]
    assert "service.shutdown_stop_failed" not in events
    assert events[-1] == "service.stopped"


async def _logged(daemon: Child, event: str) -> bool:
    return any(e["event"] == event for e in daemon.log_events())
