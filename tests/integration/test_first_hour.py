"""A new user's first commands, run as the README writes them, each its own process.

The simulator, the commissioning tools and a config without serial settings all take each
protocol's factory settings (FC 9600 8E1, Mitsubishi 19200 8E2, ENC 9600 8N1), so
``fcmaster sim --addresses 1-8`` and then ``fcmaster scan --port PTY`` find the drives with
no option given; a scan that finds nothing says what to try.
"""

from __future__ import annotations

import asyncio
import re
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import pytest

from fcmaster.protocol.registry import NAMES, spec_for
from tests.integration.commissioning import LIMIT_S
from tests.integration.daemon_harness import child


@asynccontextmanager
async def _sim(tmp_path: Path, *args: str) -> AsyncIterator[tuple[str, str]]:
    """``fcmaster sim ARGS`` in its own process: the bus name and pty path it printed."""
    async with asyncio.timeout(2 * LIMIT_S), child("sim", *args, log=tmp_path / "sim.log") as sim:
        name, path = (await sim.readline()).split()
        yield name, path


async def _run(*args: str) -> tuple[int, str, str]:
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "fcmaster", *args,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    out, err = await process.communicate()
    assert process.returncode is not None
    return process.returncode, out.decode(), err.decode()


async def test_the_readme_recipe_sim_then_scan_with_no_options_finds_the_drives(
    tmp_path: Path,
) -> None:
    async with _sim(tmp_path, "--addresses", "1-8") as (name, path):
        code, out, err = await _run("scan", "--port", path)
    assert name == "line1"
    assert code == 0, err
    assert "Traceback" not in err
    found = [int(m[1]) for m in re.finditer(r"^\s+(\d+)  status 0x[0-9A-F]{4}", out, re.M)]
    assert found == list(range(1, 9)), out


@pytest.mark.parametrize("protocol", NAMES[1:])
async def test_sim_and_scan_of_each_protocol_agree_on_its_factory_settings(
    tmp_path: Path, protocol: str
) -> None:
    first = spec_for(protocol).addresses().start + 1
    addresses = f"{first}-{first + 2}"
    async with _sim(tmp_path, "--protocol", protocol, "--addresses", addresses) as (_, path):
        code, out, err = await _run(
            "scan", "--port", path, "--protocol", protocol, "--addresses", addresses
        )
    assert code == 0, err
    # A Modbus RTU drive's status needs its profile (none given to a scan): it answers.
    assert len(re.findall(r"^\s+\d+  (?:status 0x|answers)", out, re.M)) == 3, out


async def test_a_scan_that_finds_nothing_names_the_rates_to_try_and_the_doctor(
    tmp_path: Path,
) -> None:
    async with _sim(tmp_path, "--addresses", "1-2") as (_, path):
        code, out, err = await _run(
            "scan", "--port", path, "--baudrate", "19200", "--addresses", "1-2",
            "--timeout", "0.05",
        )  # fmt: skip
    assert code == 1
    assert f"no drive answered on {path} (2 addresses tried)" in out
    assert "tried danfoss-fc at 19200 8E1" in err
    assert "--baudrate 115200 / 76800 / 57600 / 38400 / 9600 / 4800 / 2400" in err
    assert f"fcmaster doctor --port {path}" in err


async def test_status_as_text_keeps_each_key_apart_and_a_silent_drive_is_one_line(
    tmp_path: Path,
) -> None:
    async with _sim(tmp_path, "--addresses", "1-2") as (_, path):
        code, out, err = await _run("status", "--port", path, "--address", "2")
        assert code == 0, err
        silent = await _run("status", "--port", path, "--address", "9", "--timeout", "0.05")
    rows = [row for row in out.splitlines() if not row.startswith(" ")]
    for row in rows:
        assert re.fullmatch(r"[a-z_]+", row.partition("  ")[0]), row  # no key runs into its value
    assert "output_frequency_updated_at  20" in out
    assert re.search(r"^  16-14 Motor Current +0\.0 A$", out, re.M), out
    code, out, err = silent
    assert code == 1
    assert out == ""
    assert err == f"fcmaster status: no reply from address 9 on {path}\n"  # no log records
