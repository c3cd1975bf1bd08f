"""The commissioning commands (`scan`, `status`, `read`, `write`, `control`) on an ENC line.

Each command runs as its own `python -m fcmaster` process against simulated ENC drives
served on a pseudo-terminal by the test's event loop, as a technician would run them
against a real line.
"""

from __future__ import annotations

import json
from contextlib import AbstractAsyncContextManager
from pathlib import Path

from fcmaster.sim import DriveSettings, LineSettings, PtyServer
from fcmaster.sim.enc import EncSimDrive
from tests.integration import commissioning

ADDRESSES = (1, 2, 5)


def served() -> AbstractAsyncContextManager[PtyServer]:
    settings = DriveSettings(response_delay_s=0.005, parameters={"F0.08": 1.0, "F0.09": 1.0})
    running = DriveSettings(response_delay_s=0.005, running_hz=20.0)
    return commissioning.served(
        LineSettings(protocol="enc", baudrate=9600, parity="N"),  # ENC's factory 9600 8N1
        [(a, running if a == 5 else settings) for a in ADDRESSES],
    )


async def fcmaster(server: PtyServer, *args: str) -> tuple[int, str, str]:
    return await commissioning.fcmaster(server, "enc", *args)


def drive(server: PtyServer, address: int) -> EncSimDrive:
    found = next(d for d in server.line.drives if d.address == address)
    assert isinstance(found, EncSimDrive)
    return found


async def test_scan_finds_the_drives_that_answer() -> None:
    async with served() as server:
        code, out, _ = await fcmaster(server, "scan", "--addresses", "1-6", "--json")
    assert code == 0
    found = json.loads(out)
    assert [entry["address"] for entry in found] == [1, 2, 5]
    assert [entry["running"] for entry in found] == [False, False, True]
    assert found[2]["status_word"] == 0x11  # running, normal run mode


async def test_status_shows_one_drive_decoded() -> None:
    async with served() as server:
        code, out, _ = await fcmaster(server, "status", "--address", "5", "--json")
    assert code == 0
    state = json.loads(out)
    assert state["protocol"] == "enc"
    assert state["running"] is True
    assert state["output_frequency_hz"] == 20.0
    assert {k: v for k, v in state["values"]["11/0000"].items() if k != "updated_at"} == {
        "value": 20.0,
        "unit": "Hz",
        "name": "Current set frequency",
    }  # set frequency
    assert state["alarms"] == []


async def test_read_and_write_a_function_code() -> None:
    async with served() as server:
        code, _, err = await fcmaster(server, "write", "--address", "2", "F0.09", "2.5")
        assert code == 0, err
        code, out, _ = await fcmaster(server, "read", "--address", "2", "F0.09", "--json")
        assert code == 0
        assert json.loads(out) == {
            "parameter": "F0.09", "index": 0, "value": 2.5, "unit": "s", "raw": 25,
        }  # fmt: skip
        assert drive(server, 2).parameters[0x0009] == 25

        # The drive refuses a value beyond F2.17's 0-200 ms with response 30.
        code, _, err = await fcmaster(server, "write", "--address", "2", "F2.17", "300")
        assert code == 1
        assert "refused" in err
        assert "30" in err
        # A parameter the protocol cannot name is the user's mistake, not the drive's.
        code, _, err = await fcmaster(server, "read", "--address", "2", "16-13")
        assert code == 2
        assert "F0.01" in err


async def test_control_starts_stops_and_emergency_stops_a_drive() -> None:
    async with served() as server:
        sim = drive(server, 1)
        args = ("--address", "1", "--nominal-frequency", "50")
        code, _, err = await fcmaster(server, "control", *args, "start", "--frequency", "30")
        assert code == 0, err
        assert sim.control.running
        assert sim.control.set_hz == 30.0
        code, _, _ = await fcmaster(server, "control", *args, "stop")
        assert code == 0
        assert not sim.control.running

        code, _, err = await fcmaster(server, "control", *args, "start", "--frequency", "30")
        assert code == 0, err
        assert sim.control.running
        code, _, _ = await fcmaster(server, "control", *args, "quick-stop")
        assert code == 0
        assert sim.control.emergency
        assert not sim.motor.output_on

        # Beyond the given maximum is refused before anything reaches the wire.
        code, _, err = await fcmaster(
            server, "control", *args, "--max-frequency", "55", "start", "--frequency", "60"
        )
        assert code == 1
        assert "limit" in err
        assert not sim.control.running


async def test_fcmaster_sim_serves_enc_drives_that_scan_finds(tmp_path: Path) -> None:
    name, found = await commissioning.scan_a_served_sim(
        tmp_path,
        ("--protocol", "enc", "--addresses", "3-4", "--baudrate", "9600",
         "--parity", "N", "--fault-encoding", "decimal"),
        ("--protocol", "enc", "--addresses", "1-5", "--fault-encoding", "decimal"),
    )  # fmt: skip
    assert name == "line1"
    assert found == [3, 4]
