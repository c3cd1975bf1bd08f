"""`fcmaster params backup | diff | restore` against simulated lines of each protocol.

Each command runs as its own `python -m fcmaster` process on a pseudo-terminal served by the
test's event loop. Changes "by hand" are made in the simulated drive's own store, so what the
tool reports is checked against what the drive really holds.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import sys
from pathlib import Path
from typing import Any, TypeVar

import yaml

from fcmaster.sim import DriveSettings, LineSettings, PtyServer
from fcmaster.sim.danfoss_fc import FcSimDrive
from fcmaster.sim.enc import EncSimDrive
from fcmaster.sim.mitsubishi import MitsubishiSimDrive
from tests.integration import commissioning

FC_LINE = LineSettings(protocol="danfoss-fc", baudrate=9600, parity="E")
MITSUBISHI_LINE = LineSettings(protocol="mitsubishi", baudrate=19200, parity="E", stopbits=2)
ENC_LINE = LineSettings(protocol="enc", baudrate=9600, parity="N")
T = TypeVar("T")


def sim_drive(server: PtyServer, address: int, kind: type[T]) -> T:
    found = next(d for d in server.line.drives if d.address == address)
    assert isinstance(found, kind)
    return found


def saved(path: Path) -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load(path.read_text())
    return data


async def test_fc_backup_diff_restore_round_trip(tmp_path: Path) -> None:
    backup = tmp_path / "drive1.yaml"
    async with commissioning.served(
        FC_LINE, [(1, DriveSettings()), (2, DriveSettings())]
    ) as server:
        fc = "danfoss-fc"
        code, _, err = await params(server, fc, "backup", "--address", "1", "-o", str(backup))
        assert code == 0, err
        data = saved(backup)
        assert (data["protocol"], data["address"]) == ("danfoss-fc", 1)
        assert data["identity"]["15-40"]["value"] == "FC-302"
        assert data["identity"]["15-51"]["value"] == "001123G456"  # the simulator's serial
        assert data["parameters"]["3-41"] == {
            "name": "Ramp 1 Ramp Up Time", "value": 3.0, "unit": "s", "raw": 300,
        }  # fmt: skip
        assert data["parameters"]["8-35"]["raw"] == 10  # 10 ms, as the drive holds it
        assert "16-13" not in data["parameters"]  # a reading, not a setting

        drive = sim_drive(server, 1, FcSimDrive)
        drive.parameters.set(341, 550)  # 3-41 changed at the panel: 5.50 s
        code, out, err = await params(server, fc, "diff", "--address", "1", str(backup))
        assert code == 1, err
        rows = [line.split() for line in out.splitlines() if line.startswith("3-")]
        assert rows == [["3-41", "Ramp", "1", "Ramp", "Up", "Time", "3", "s", "5.5", "s"]]
        assert "1 of 19 parameters differ" in out

        code, out, err = await params(server, fc, "restore", "--address", "1", str(backup))
        assert code == 0, err + out
        assert "3-41" in out
        assert "read back 3 s" in out
        assert drive.parameters[341] == 300
        code, out, err = await params(server, fc, "diff", "--address", "1", str(backup))
        assert code == 0, err + out
        assert "no differences" in out


async def test_fc_restore_refuses_another_drive_type_unless_forced(tmp_path: Path) -> None:
    backup = tmp_path / "drive1.yaml"
    async with commissioning.served(FC_LINE, [(1, DriveSettings())]) as server:
        fc = "danfoss-fc"
        code, _, err = await params(server, fc, "backup", "--address", "1", "-o", str(backup))
        assert code == 0, err
        data = saved(backup)
        data["identity"]["15-40"]["value"] = "FC-301"
        data["parameters"]["3-42"].update(value=4.0, raw=400)
        backup.write_text(yaml.safe_dump(data))
        drive = sim_drive(server, 1, FcSimDrive)
        code, _, err = await params(server, fc, "restore", "--address", "1", str(backup))
        assert code == 2
        assert "FC-301" in err
        assert "--force" in err
        assert drive.parameters[342] == 300  # nothing written
        code, out, err = await params(
            server, fc, "restore", "--address", "1", "--force", str(backup)
        )
        assert code == 0, err + out
        assert drive.parameters[342] == 400


async def test_two_files_compare_without_a_port(tmp_path: Path) -> None:
    one, two = tmp_path / "one.yaml", tmp_path / "two.yaml"
    other = DriveSettings(parameters={"3-42": 7.0})
    async with commissioning.served(FC_LINE, [(1, DriveSettings()), (2, other)]) as server:
        for address, path in (("1", one), ("2", two)):
            code, _, err = await params(
                server, "danfoss-fc", "backup", "--address", address, "-o", str(path)
            )
            assert code == 0, err
    code, out, err = await _fcmaster("params", "diff", str(one), str(two))
    assert code == 1, err
    # 8-31 is each drive's own address: a real difference between two drives' sets.
    assert [line.split()[0] for line in out.splitlines()[1:-1]] == ["3-42", "8-31"]
    assert "3 s" in out
    assert "7 s" in out
    code, out, _ = await _fcmaster("params", "diff", str(one), str(one))
    assert code == 0
    assert "no differences" in out
    # Bad input: exit 2 with the reason.
    junk = tmp_path / "junk.yaml"
    junk.write_text("protocol: [\n")
    code, _, err = await _fcmaster("params", "diff", str(one), str(junk))
    assert code == 2
    assert "not YAML" in err
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text(yaml.safe_dump({"format": "x", "protocol": "danfoss-fc"}))
    code, _, err = await _fcmaster("params", "diff", str(one), str(wrong))
    assert code == 2
    assert "format" in err
    assert "address" in err
    assert "parameters" in err  # every problem at once
    code, _, err = await _fcmaster("params", "diff", str(one))
    assert code == 2
    code, out, _ = await _fcmaster("params", "diff", "--help")
    assert "1 they differ" in out


async def params(server: PtyServer, protocol: str, verb: str, *args: str) -> tuple[int, str, str]:
    """``fcmaster params VERB --port PTY --protocol PROTOCOL ARGS``."""
    return await _fcmaster("params", verb, "--port", server.device, "--protocol", protocol, *args)


async def _fcmaster(*args: str) -> tuple[int, str, str]:
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "fcmaster", *args,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    out, err = await process.communicate()
    assert process.returncode is not None
    return process.returncode, out.decode(), err.decode()


async def test_mitsubishi_restore_waits_for_a_stopped_motor(tmp_path: Path) -> None:
    backup = tmp_path / "station3.yaml"
    running = DriveSettings(running_hz=20.0)
    async with commissioning.served(
        MITSUBISHI_LINE, [(3, DriveSettings()), (10, running)]
    ) as server:
        mit = "mitsubishi"
        code, _, err = await params(server, mit, "backup", "--address", "3", "-o", str(backup))
        assert code == 0, err
        data = saved(backup)
        assert data["identity"]["H7C"]["value"]  # the model name, as the drive gave it
        assert data["parameters"]["Pr.7"] == {
            "name": "acceleration time", "value": 5.0, "unit": "s", "raw": 50,
        }  # fmt: skip
        # The simulated inverter has no Pr.331: it answers NAK, and the file says so.
        assert data["parameters"]["Pr.331"]["refused"]["code"] == 0xB  # instruction code error
        assert "Pr.331" in err

        moving = sim_drive(server, 10, MitsubishiSimDrive)
        moving.parameters.set(7, 80)
        moving.parameters.set(1, 6000)
        code, out, err = await params(server, mit, "restore", "--address", "10", str(backup))
        assert code == 1, err + out
        assert out.count("needs the motor stopped") == 2
        assert (moving.parameters[7], moving.parameters[1]) == (80, 6000)  # nothing written

        stopped = sim_drive(server, 3, MitsubishiSimDrive)
        stopped.parameters.set(7, 80)
        code, out, err = await params(server, mit, "restore", "--address", "3", str(backup))
        assert code == 0, err + out
        assert stopped.parameters[7] == 50
        assert "1 written and verified" in out


async def test_enc_round_trip_and_a_refused_write_reported(tmp_path: Path) -> None:
    backup = tmp_path / "enc1.yaml"
    async with commissioning.served(
        ENC_LINE, [(1, DriveSettings(response_delay_s=0.005))]
    ) as server:
        code, _, err = await params(server, "enc", "backup", "--address", "1", "-o", str(backup))
        assert code == 0, err
        data = saved(backup)
        assert data["parameters"]["F0.08"] == {
            "name": "Acceleration time 1", "value": 5.0, "unit": "s", "raw": 50,
        }  # fmt: skip
        drive = sim_drive(server, 1, EncSimDrive)
        drive.parameters.set(0x0008, 120, running=False)  # F0.08 = 12.0 s
        code, out, _ = await params(server, "enc", "diff", "--address", "1", str(backup))
        assert code == 1
        assert "F0.08" in out

        # F0.09 = 0 is below the drive's range: it refuses, the rest still goes in.
        data["parameters"]["F0.09"].update(value=0.0, raw=0)
        backup.write_text(yaml.safe_dump(data))
        code, out, err = await params(server, "enc", "restore", "--address", "1", str(backup))
        assert code == 1, err + out
        refusal = next(line for line in out.splitlines() if line.startswith("F0.09"))
        assert "refused by the drive" in refusal
        assert "(error 30)" in refusal  # response code 30: not accepted
        assert drive.parameters[0x0008] == 50  # F0.08 restored and verified
        assert drive.parameters[0x0009] == 50
        assert "1 written and verified, 1 not written" in out


async def test_fc_restore_on_a_running_drive_writes_nothing_that_needs_it_stopped(
    tmp_path: Path,
) -> None:
    backup = tmp_path / "drive1.yaml"
    running = DriveSettings(running_hz=20.0)
    async with commissioning.served(FC_LINE, [(1, DriveSettings()), (2, running)]) as server:
        code, _, err = await params(
            server, "danfoss-fc", "backup", "--address", "1", "-o", str(backup)
        )
        assert code == 0, err
        moving = sim_drive(server, 2, FcSimDrive)
        moving.parameters.set(341, 900)  # 3-41 ramp: the simulator would even take it running
        moving.parameters.set(412, 50)  # 4-12 low speed limit
        code, out, err = await params(
            server, "danfoss-fc", "restore", "--address", "2", str(backup)
        )
        assert code == 1, err + out
        lines = {line.split()[0]: line for line in out.splitlines() if line[:1].isdigit()}
        assert "needs the motor stopped" in lines["3-41"]
        assert "needs the motor stopped" in lines["4-12"]
        assert "left alone" in lines["8-31"]  # the other drive's address: never written
        assert (moving.parameters[341], moving.parameters[412]) == (900, 50)
        assert moving.parameters[831] == 2
        assert "0 written and verified, 2 not written, 1 line settings left alone" in out


async def test_fc_restore_writes_a_bounded_value_once_its_bound_is_in(tmp_path: Path) -> None:
    backup = tmp_path / "drive1.yaml"
    async with commissioning.served(FC_LINE, [(1, DriveSettings())]) as server:
        code, _, err = await params(
            server, "danfoss-fc", "backup", "--address", "1", "-o", str(backup)
        )
        assert code == 0, err
        data = saved(backup)
        data["parameters"]["4-12"].update(value=30.0, raw=300)
        data["parameters"]["4-14"].update(value=40.0, raw=400)
        backup.write_text(yaml.safe_dump(data))
        drive = sim_drive(server, 1, FcSimDrive)
        drive.parameters.set(414, 200)  # 20 Hz: 4-12 = 30 Hz is refused until 4-14 moves
        code, out, err = await params(
            server, "danfoss-fc", "restore", "--address", "1", str(backup)
        )
        assert code == 0, err + out
        assert (drive.parameters[412], drive.parameters[414]) == (300, 400)
        assert "2 written and verified, 0 not written" in out


async def test_a_progress_bar_on_a_terminal_and_none_in_a_pipe(tmp_path: Path) -> None:
    main, terminal = os.openpty()
    try:
        async with commissioning.served(FC_LINE, [(1, DriveSettings())]) as server:
            process = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "fcmaster", "params", "backup", "--port", server.device,
                "--address", "1", "-o", str(tmp_path / "set.yaml"),
                stdout=asyncio.subprocess.DEVNULL, stderr=terminal,
            )  # fmt: skip
            assert await process.wait() == 0
        os.set_blocking(main, False)
        shown = b""
        with contextlib.suppress(BlockingIOError, OSError):
            while chunk := os.read(main, 4096):
                shown += chunk
    finally:
        os.close(main)
        os.close(terminal)
    text = shown.decode()
    assert "\r[" in text
    assert "] 24/24" in text  # 5 identity texts and 19 settings
    # Through a pipe (every other test): the summary only, no bar.
    async with commissioning.served(FC_LINE, [(1, DriveSettings())]) as server:
        code, _, err = await params(server, "danfoss-fc", "backup", "--address", "1")
    assert code == 0
    assert "[" not in err
    assert "19 parameters saved" in err
