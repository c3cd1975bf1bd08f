"""`fcmaster params backup | diff | restore` of Modbus RTU drives, through their profiles.

A Modbus drive's set is what its drive profile lists (its settings, then its watchdog's
registers). Each command runs as its own `python -m fcmaster` process on a pseudo-terminal
served by the simulator; changes "by hand" are made in the simulated drive's own registers,
so what the tool reports is checked against what the drive holds. The Yaskawa drive hears
nothing for its profile's wait after a parameter write, as the family's drives do: a
restore that did not keep the wait would find it deaf when it reads back.
"""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path
from typing import Any

import yaml

from fcmaster.sim import DriveSettings, LineSettings, PtyServer
from fcmaster.sim.modbus_rtu.drive import ModbusSimDrive
from tests.integration import commissioning

LINE = LineSettings(protocol="modbus-rtu", baudrate=19200, parity="E")
YASKAWA = "yaskawa-memobus"
C1_01, C1_02, H5_09 = 0x0200, 0x0201, 0x0435  # acceleration, deceleration, CE detection time


def sim_drive(server: PtyServer, address: int) -> ModbusSimDrive:
    found = next(d for d in server.line.drives if d.address == address)
    assert isinstance(found, ModbusSimDrive)
    return found


async def params(
    server: PtyServer, verb: str, *args: str, profile: str | None = YASKAWA
) -> tuple[int, str, str]:
    """``fcmaster params VERB --port PTY --protocol modbus-rtu --profile PROFILE ARGS``."""
    chosen = () if profile is None else ("--profile", profile)
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "fcmaster", "params", verb, "--port", server.device,
        "--protocol", "modbus-rtu", *chosen, *args,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    out, err = await process.communicate()
    assert process.returncode is not None
    return process.returncode, out.decode(), err.decode()


async def test_a_profiles_settings_are_backed_up_compared_and_restored(tmp_path: Path) -> None:
    backup = tmp_path / "yaskawa.yaml"
    drives = [(4, DriveSettings(profile=YASKAWA, parameters={"hr1077": 20}))]  # H5-09 2.0 s (raw)
    async with commissioning.served(LINE, drives) as server:
        code, _, err = await params(server, "backup", "--address", "4", "-o", str(backup))
        assert code == 0, err
        data: dict[str, Any] = yaml.safe_load(backup.read_text())
        assert (data["protocol"], data["address"]) == ("modbus-rtu", 4)
        assert data["parameters"] == {
            "hr512": {"name": "C1-01 Acceleration Time 1", "value": 10.0, "unit": "s", "raw": 100},
            "hr513": {"name": "C1-02 Deceleration Time 1", "value": 10.0, "unit": "s", "raw": 100},
            "hr1077": {"name": "Communication watchdog timeout", "value": 2.0, "unit": "s",
                       "raw": 20},
            "hr1064": {"name": "Communication watchdog action", "value": 0.0, "raw": 0},
            "hr1065": {"name": "Communication watchdog enable", "value": 0.0, "raw": 0},
        }  # fmt: skip

        drive = sim_drive(server, 4)
        drive.stored[(False, C1_01)] = 55  # C1-01 changed at the panel: 5.5 s
        drive.stored[(False, H5_09)] = 50  # and the CE detection time: 5.0 s
        code, out, err = await params(server, "diff", "--address", "4", str(backup))
        assert code == 1, err
        rows = [line.split() for line in out.splitlines() if line.startswith("hr")]
        assert [row[0] for row in rows] == ["hr512", "hr1077"]
        assert "2 of 5 parameters differ" in out

        code, out, err = await params(server, "restore", "--address", "4", str(backup))
        assert code == 0, err + out
        assert "hr512" in out
        assert "read back 10 s" in out
        assert "2 written and verified, 0 not written" in out
        assert drive.stored[(False, C1_01)] == 100
        assert drive.stored[(False, H5_09)] == 20
        # each write's read-back came after the drive's wait: it never went unheard
        assert drive.unheard == 0
        code, out, err = await params(server, "diff", "--address", "4", str(backup))
        assert code == 0, err + out
        assert "no differences in 5 parameters" in out


async def test_a_set_is_the_profiles_and_a_line_without_one_has_none(tmp_path: Path) -> None:
    backup = tmp_path / "yaskawa.yaml"
    drives = [(4, DriveSettings(profile=YASKAWA)), (1, DriveSettings(profile="abb-drives"))]
    async with commissioning.served(LINE, drives) as server:
        code, _, err = await params(server, "backup", "--address", "4", "-o", str(backup))
        assert code == 0, err
        # the Yaskawa set, restored through the ABB profile: its registers are not that set's
        code, _, err = await params(
            server, "restore", "--address", "1", str(backup), profile="abb-drives"
        )
        assert code == 2
        assert "hr512 (C1-01 Acceleration Time 1): not in the modbus-rtu parameter set" in err
        assert "nothing was written" in err
        # without a profile there is no set to speak of
        code, _, err = await params(server, "backup", "--address", "4", profile=None)
        assert code == 2
        assert "--profile" in err
        assert "Traceback" not in err
