"""The commissioning commands (`scan`, `status`, `read`, `write`, `control`) on a Mitsubishi line.

Each command runs as its own `python -m fcmaster` process against simulated inverters at
the factory line settings (19200 8E2, CR, waiting time in the frame) served on a
pseudo-terminal by the test's event loop, as a technician would run them on a real line.
"""

from __future__ import annotations

import json
import time
from contextlib import AbstractAsyncContextManager
from pathlib import Path

from fcmaster.sim import DriveSettings, LineSettings, PtyServer
from fcmaster.sim.mitsubishi import MitsubishiSimDrive
from tests.integration import commissioning

STATIONS = (0, 3, 10)


def served() -> AbstractAsyncContextManager[PtyServer]:
    running = DriveSettings(running_hz=20.0)
    return commissioning.served(
        LineSettings(protocol="mitsubishi", baudrate=19200, parity="E", stopbits=2),
        [(a, running if a == 10 else DriveSettings()) for a in STATIONS],
    )


async def fcmaster(server: PtyServer, *args: str) -> tuple[int, str, str]:
    return await commissioning.fcmaster(server, "mitsubishi", *args)


def drive(server: PtyServer, address: int) -> MitsubishiSimDrive:
    found = next(d for d in server.line.drives if d.address == address)
    assert isinstance(found, MitsubishiSimDrive)
    return found


async def test_scan_finds_the_stations_that_answer_station_0_included() -> None:
    async with served() as server:
        code, out, err = await fcmaster(server, "scan", "--addresses", "0-11", "--json")
    assert code == 0, err
    found = json.loads(out)
    assert [entry["address"] for entry in found] == [0, 3, 10]
    assert [entry["running"] for entry in found] == [False, False, True]
    assert found[2]["status_word"] == 0x4B  # RUN, forward, up to frequency, FU (H7A)


async def test_status_shows_one_drive_decoded() -> None:
    async with served() as server:
        code, out, err = await fcmaster(server, "status", "--address", "10", "--json")
    assert code == 0, err
    state = json.loads(out)
    assert state["protocol"] == "mitsubishi"
    assert (state["running"], state["fault"], state["direction"]) == (True, False, "forward")
    assert state["output_frequency_hz"] == 20.0
    assert {k: v for k, v in state["values"]["H6F"].items() if k != "updated_at"} == {
        "value": 20.0,
        "unit": "Hz",
        "name": "output frequency",
    }
    assert state["values"]["H71"]["unit"] == "V"
    assert state["alarms"] == []


async def test_read_and_write_a_parameter_through_its_page() -> None:
    async with served() as server:
        code, _, err = await fcmaster(server, "write", "--address", "3", "Pr.7", "2.5")
        assert code == 0, err
        assert drive(server, 3).parameters[7] == 25
        code, out, err = await fcmaster(server, "read", "--address", "3", "Pr.7", "--json")
        assert code == 0, err
        assert json.loads(out) == {
            "parameter": "Pr.7", "index": 0, "value": 2.5, "unit": "s", "raw": 25,
        }  # fmt: skip
        code, out, _ = await fcmaster(server, "read", "--address", "3", "Pr.122", "--json")
        assert code == 0
        assert json.loads(out)["value"] == 9999.0  # no communication check in the simulator

        # The drive refuses a value beyond the parameter's range: NAK C, exit 1.
        code, _, err = await fcmaster(server, "write", "--address", "3", "Pr.7", "4000")
        assert code == 1
        assert "refused" in err
        assert "Data range" in err
        # A name the protocol cannot address is the user's mistake, not the drive's.
        code, _, err = await fcmaster(server, "read", "--address", "3", "16-13")
        assert code == 2
        code, _, err = await fcmaster(server, "read", "--address", "32", "H7A")
        assert code == 2
        assert "0-31" in err


async def test_control_starts_stops_and_resets_a_drive() -> None:
    async with served() as server:
        sim = drive(server, 0)
        args = ("--address", "0", "--nominal-frequency", "50")
        code, _, err = await fcmaster(server, "control", *args, "start", "--frequency", "30")
        assert code == 0, err
        assert sim.control.set_hz == 30.0
        assert sim.control.run_bits == 0x02  # STF
        code, _, err = await fcmaster(server, "control", *args, "reverse")
        assert code == 0, err
        assert sim.control.run_bits == 0x04  # STR
        code, _, _ = await fcmaster(server, "control", *args, "stop")
        assert code == 0
        assert sim.control.run_bits == 0

        before = time.monotonic()
        code, _, err = await fcmaster(server, "control", *args, "reset")
        assert code == 0, err  # no reply expected, none waited for
        assert sim.deaf_until > before  # HFD 9696 reached it: the drive is restarting

        # Beyond the given maximum is refused before anything reaches the wire.
        code, _, err = await fcmaster(
            server, "control", *args, "--max-frequency", "55", "start", "--frequency", "60"
        )
        assert code == 1
        assert "limit" in err
        code, _, err = await fcmaster(server, "control", *args, "jog")
        assert code != 0
        assert "jog" in err


async def test_fcmaster_sim_serves_mitsubishi_drives_that_scan_finds(tmp_path: Path) -> None:
    name, found = await commissioning.scan_a_served_sim(
        tmp_path,
        ("--protocol", "mitsubishi", "--addresses", "0-1", "--stopbits", "2"),
        ("--protocol", "mitsubishi", "--addresses", "0-3"),
    )
    assert name == "line1"
    assert found == [0, 1]


async def test_line_options_follow_drives_set_to_cr_lf_and_their_own_waiting_time() -> None:
    # Pr.124 = 2: frames end CR LF; Pr.123 = 20: the drive keeps its own waiting time, so
    # requests leave the waiting-time digit out.
    own = DriveSettings(parameters={"Pr.124": 2.0, "Pr.123": 20.0})
    line = LineSettings(protocol="mitsubishi", baudrate=19200, parity="E", stopbits=2)
    async with commissioning.served(line, [(4, own)]) as server:
        sim = drive(server, 4)
        heard: list[bytes] = []
        answer = sim.handle

        def recording(frame: bytes, now: float) -> bytes | None:
            heard.append(frame)
            return answer(frame, now)

        sim.handle = recording  # type: ignore[method-assign]
        options = ("--address", "4", "--json", "--terminator", "crlf", "--wait-time-ms", "none")
        code, out, err = await fcmaster(server, "status", *options)
        assert code == 0, err
        assert json.loads(out)["address"] == 4
        # ENQ, station 04, instruction 7A, no waiting digit, the sum, CR LF
        status_request = b"\x05047A" + b"%02X" % (sum(b"047A") & 0xFF) + b"\r\n"
        assert status_request in heard

        code, _, err = await fcmaster(server, "status", "--address", "4", "--wait-time-ms", "15")
        assert code == 2
        assert "steps of 10" in err
