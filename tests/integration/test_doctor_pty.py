"""`fcmaster doctor` as a technician runs it: a process against simulated drives on a pty,
one hardware fault at a time, each named with its fix (and the same as JSON)."""

from __future__ import annotations

import asyncio
import json
import os
import sys
from pathlib import Path
from typing import Any

import pytest

from fcmaster.sim import DriveSettings, FaultPlan, LineSettings, PtyServer
from tests.integration import commissioning

TWO = [(1, DriveSettings()), (2, DriveSettings())]
FC_19200 = LineSettings(protocol="danfoss-fc", baudrate=19200, parity="E")


async def doctor(server: PtyServer, *args: str) -> tuple[int, str, str]:
    """``fcmaster doctor --port PTY ARGS``: exit code, stdout, stderr."""
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "fcmaster", "doctor", "--port", server.device, *args,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    out, err = await process.communicate()
    assert process.returncode is not None
    return process.returncode, out.decode(), err.decode()


async def doctor_json(server: PtyServer, *args: str) -> tuple[int, dict[str, Any]]:
    code, out, err = await doctor(server, *args, "--json")
    assert out, err
    return code, json.loads(out)


def finding(report: dict[str, Any], code: str) -> dict[str, Any]:
    found: list[dict[str, Any]] = [f for f in report["findings"] if f["code"] == code]
    assert found, f"no {code} finding in {report['findings']}"
    return found[0]


@pytest.mark.parametrize(
    ("line", "args"),
    [
        (FC_19200, ("--protocol", "danfoss-fc")),
        (LineSettings(protocol="mitsubishi", baudrate=19200, parity="E", stopbits=2),
         ("--protocol", "mitsubishi")),
        # No --protocol: FC and Mitsubishi are tried at every rate before ENC answers.
        (LineSettings(protocol="enc", baudrate=9600, parity="N"), ()),
        # Answering 10 ms after a request is no fault of a Modbus drive: none is reported.
        (LineSettings(protocol="modbus-rtu", baudrate=19200, parity="E"),
         ("--protocol", "modbus-rtu")),
        # No --protocol: FC, Mitsubishi and ENC are tried at every rate before Modbus RTU.
        (LineSettings(protocol="modbus-rtu", baudrate=9600, parity="E"), ()),
    ],
    ids=["danfoss-fc", "mitsubishi", "enc-found-without-protocol", "modbus-rtu",
         "modbus-rtu-found-without-protocol"],
)  # fmt: skip
async def test_a_healthy_line_of_each_protocol(line: LineSettings, args: tuple[str, ...]) -> None:
    async with commissioning.served(line, TWO) as server:
        code, report = await doctor_json(server, *args, "--addresses", "1-3")
    assert report["findings"] == []
    assert (code, report["healthy"]) == (0, True)
    found = report["line"]
    assert (found["protocol"], found["baudrate"], found["parity"]) == (
        line.protocol, line.baudrate, line.parity,
    )  # fmt: skip
    assert report["drives"] == [1, 2]
    assert report["echoes"] == 0
    assert [a["answered"] for a in report["addresses"]] == [3, 3]


async def test_drives_at_another_baud_rate_than_the_config_says(tmp_path: Path) -> None:
    async with commissioning.served(FC_19200, TWO) as server:
        config = tmp_path / "plant.yaml"
        config.write_text(
            f"buses:\n  - name: north\n    port: {server.device}\n    baudrate: 9600\n"
            "    drives: [{name: pump, address: 1}]\n"
        )
        code, out, _ = await doctor(server, "--config", str(config), "--addresses", "1-3")
        assert code == 1
        assert (
            "drives answer at 19200 8E1 (danfoss-fc) but the config (bus north) says "
            "baudrate 9600" in out
        )
        assert "  fix     set baudrate: 19200 on bus north" in out
        # The faster rates were tried first, and the simulated drives heard them as garbage.
        assert server.line.counters.misframed_bytes > 0
        code, report = await doctor_json(server, "--config", str(config), "--addresses", "1-3")
    assert code == 1
    settings = finding(report, "settings")
    assert settings["fix"] == "set baudrate: 19200 on bus north"
    assert settings["found"]["baudrate"] == 19200
    assert settings["config"]["baudrate"] == 9600
    assert report["config_bus"] == "north"
    assert [f["code"] for f in report["findings"]] == ["settings"]


async def test_an_echoing_adapter() -> None:
    line = LineSettings(protocol="danfoss-fc", baudrate=19200, faults=FaultPlan(echo=True))
    async with commissioning.served(line, TWO) as server:
        code, out, _ = await doctor(server, "--protocol", "danfoss-fc", "--addresses", "1-3")
        assert code == 1
        assert "problem   the adapter echoes:" in out
        assert "  fix     set echo: true on the bus" in out
        code, report = await doctor_json(server, "--protocol", "danfoss-fc", "--addresses", "1-3")
    echo = finding(report, "echo")
    assert echo["echoes"] == echo["requests"] == report["requests"]
    assert report["drives"] == [1, 2]  # the echo hides no drive
    assert [f["code"] for f in report["findings"]] == ["echo"]


async def test_two_drives_on_one_address() -> None:
    line = LineSettings(protocol="danfoss-fc", baudrate=19200, duplicate_addresses=True)
    drives = [(1, DriveSettings()), (2, DriveSettings()), (2, DriveSettings())]
    async with commissioning.served(line, drives) as server:
        code, out, _ = await doctor(server, "--protocol", "danfoss-fc", "--addresses", "1-4")
        assert code == 1
        assert "problem   two drives answer at address 2 (garbled replies in 3 of 3" in out
        assert "fix     give one of them another address with 8-31 (e.g. 3," in out
        code, report = await doctor_json(server, "--protocol", "danfoss-fc", "--addresses", "1-4")
        assert server.line.counters.collisions >= 3
    assert [f["code"] for f in report["findings"]] == ["duplicate_address"]
    assert finding(report, "duplicate_address")["address"] == 2
    assert report["drives"] == [1, 2]
    twins = next(a for a in report["addresses"] if a["address"] == 2)
    assert twins["collides"] is True
    assert twins["answered"] == 0


async def test_noise_on_the_line() -> None:
    line = LineSettings(protocol="danfoss-fc", baudrate=19200,
                        faults=FaultPlan(noise=0.5, seed=7))  # fmt: skip
    async with commissioning.served(line, TWO) as server:
        code, report = await doctor_json(server, "--protocol", "danfoss-fc", "--addresses", "1-6")
        bursts = server.line.counters.noise_bursts
    assert code == 1
    noise = finding(report, "noise")
    assert bursts > 0
    assert 3 <= noise["noise_bytes"] <= 6 * bursts  # each burst is 1-6 bytes
    assert "120 ohm" in noise["fix"]
    assert report["drives"] == [1, 2]  # noise is not mistaken for a drive or a collision
    assert [f["code"] for f in report["findings"]] == ["noise"]


async def test_no_drive_on_the_line() -> None:
    async with commissioning.served(FC_19200, []) as server:
        code, out, _ = await doctor(server, "--protocol", "danfoss-fc", "--addresses", "1-3")
        assert code == 1
        assert "problem   no drive answered on" in out
        assert "at any of 24 line settings" in out  # 8 rates × 3 parities
        code, report = await doctor_json(server, "--protocol", "danfoss-fc", "--addresses", "1-3")
    assert report["line"] is None
    assert report["drives"] == []
    assert [f["code"] for f in report["findings"]] == ["no_answer"]


async def test_an_adapter_holding_replies_for_16_ms() -> None:
    line = LineSettings(protocol="danfoss-fc", baudrate=115200, adapter_latency_ms=16)
    async with commissioning.served(line, TWO) as server:
        code, report = await doctor_json(server, "--protocol", "danfoss-fc", "--addresses", "1-3")
    assert code == 1
    slow = finding(report, "slow_replies")
    assert slow["turnaround_ms"] > 15.0  # the drives' 10 ms and about 8 ms held on average
    assert "latency timer" in slow["fix"]
    assert report["drives"] == [1, 2]


async def test_bad_input_exits_2() -> None:
    async with commissioning.served(FC_19200, TWO) as server:
        code, _, err = await doctor(server, "--protocol", "danfoss-fc", "--addresses", "5-1")
        assert code == 2
        assert "runs backwards" in err
        code, _, err = await doctor(server, "--config", "/nonexistent/plant.yaml")
        assert code == 2


async def test_two_drives_on_one_address_that_answer_one_after_the_other() -> None:
    # Different response delays (8-35): the replies do not overlap, both check, one is extra.
    line = LineSettings(protocol="danfoss-fc", baudrate=19200, duplicate_addresses=True)
    drives = [(1, DriveSettings()), (1, DriveSettings(response_delay_s=0.025))]
    async with commissioning.served(line, drives) as server:
        code, report = await doctor_json(server, "--protocol", "danfoss-fc", "--addresses", "1-3")
        assert server.line.counters.collisions == 0
    assert code == 1
    duplicate = finding(report, "duplicate_address")
    assert duplicate["address"] == 1
    assert "doubled replies in 3 of 3 attempts" in duplicate["message"]
    assert [f["code"] for f in report["findings"]] == ["duplicate_address"]  # not noise


async def test_progress_is_shown_on_a_terminal_and_cleared() -> None:
    terminal, stderr = os.openpty()  # the doctor's stderr is a terminal, as a technician's is
    try:
        async with commissioning.served(FC_19200, TWO) as server:
            process = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "fcmaster", "doctor", "--port", server.device,
                "--protocol", "danfoss-fc", "--addresses", "1-3",
                stdout=asyncio.subprocess.PIPE, stderr=stderr,
            )  # fmt: skip
            out, _ = await process.communicate()
        os.set_blocking(terminal, False)
        shown = os.read(terminal, 1 << 16).decode()
    finally:
        os.close(terminal)
        os.close(stderr)
    assert process.returncode == 0, out
    assert "setting 1/24: danfoss-fc 115200 8E1" in shown
    assert "setting 13/24: danfoss-fc 19200 8E1" in shown
    assert "scanning address 3 (3/3), found 2" in shown
    assert shown.endswith("\r\x1b[K")  # the last progress line is wiped before the report
    assert "\x1b[K" not in out.decode()  # the report itself is plain
