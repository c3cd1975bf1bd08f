"""`fcmaster sim --config FILE` links each bus's port to a pty; the same file runs the daemon."""

import asyncio
import os
import signal
import subprocess
import sys
from pathlib import Path

from fcmaster.config import load
from fcmaster.service import Service

CONFIG = """
buses:
  - name: north
    port: {north}
    baudrate: 38400
    drives:
      - {{name: pump-1, address: 1, control: bus}}
      - {{name: pump-2, address: 2}}
    simulation:
      drives:
        1: {{running_hz: 30}}
  - name: south
    port: {south}
    baudrate: 19200
    drives:
      - {{name: fan-1, address: 5}}
"""


def _start_sim(config: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "fcmaster", "sim", "--config", str(config)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _link_targets(*paths: Path) -> list[str | None]:
    """Where each path links to (None: it is not a link, or does not exist)."""
    return [os.readlink(p) if os.path.islink(p) else None for p in paths]


async def _lines(process: subprocess.Popen[str], count: int) -> list[str]:
    assert process.stdout is not None
    stdout = process.stdout
    return [await asyncio.wait_for(asyncio.to_thread(stdout.readline), 15) for _ in range(count)]


async def test_the_same_file_serves_the_drives_and_runs_the_daemon(tmp_path: Path) -> None:
    north, south = tmp_path / "ttyNORTH", tmp_path / "ttySOUTH"
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(north=north, south=south))
    with _start_sim(config) as sim:
        await _serve_and_run(sim, config, north, south)


async def _serve_and_run(
    sim: subprocess.Popen[str], config: Path, north: Path, south: Path
) -> None:
    try:
        lines = await _lines(sim, 2)
        assert [line.split()[0] for line in lines] == ["north", "south"]
        assert {line.split()[1] for line in lines} == {str(north), str(south)}
        targets = _link_targets(north, south)
        assert all(t is not None and t.startswith("/dev/pts/") for t in targets), targets

        service = Service(load(config))
        runner = asyncio.create_task(service.run(install_signals=False))
        try:
            await service.hub.wait_for(
                lambda: all(s.online for s in service.fleet.snapshot()), timeout_s=20
            )
            pump = service.fleet.get("north", "pump-1")
            assert pump is not None
            assert pump.running  # found running at 30 Hz, adopted as it is
            assert pump.output_frequency_hz is not None
            assert abs(pump.output_frequency_hz - 30.0) < 1.0
        finally:
            service.stop()
            await asyncio.wait_for(runner, 10)

        sim.send_signal(signal.SIGTERM)
        assert await asyncio.wait_for(asyncio.to_thread(sim.wait), 10) == 0
        assert _link_targets(north, south) == [None, None]  # links removed on the way out
    finally:
        if sim.poll() is None:
            sim.kill()
            sim.wait()


async def test_a_port_path_that_is_a_real_file_is_never_replaced(tmp_path: Path) -> None:
    north, south = tmp_path / "ttyNORTH", tmp_path / "ttySOUTH"
    south.write_text("not a link")
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(north=north, south=south))
    with _start_sim(config) as sim:
        try:
            code = await asyncio.wait_for(asyncio.to_thread(sim.wait), 15)
        finally:
            if sim.poll() is None:
                sim.kill()
                sim.wait()
        assert sim.stderr is not None
        message = sim.stderr.read()
    assert code == 1
    assert "is not a symbolic link" in message
    assert south.read_text() == "not a link"
    assert not north.exists()  # the line linked before it was unlinked again
