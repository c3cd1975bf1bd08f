"""`fcmaster params restore` judges the whole file before a byte goes on the line.

Each restore runs as its own `python -m fcmaster` process on a pseudo-terminal served by the
test's event loop; every byte the master puts on the line and every request frame the
simulated drive hears is recorded, so "nothing written" is checked on the wire, not only in
the drive's store.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from fcmaster.protocol.danfoss_fc.telegram import RequestAk, decode_telegram
from fcmaster.protocol.mitsubishi.message import Request, decode_frame
from fcmaster.protocol.parameter_set import ParameterSet
from fcmaster.sim import DriveSettings, PtyServer
from fcmaster.sim.danfoss_fc import FcSimDrive
from fcmaster.sim.mitsubishi import MitsubishiSimDrive
from tests.integration import commissioning
from tests.integration.test_params_commission import (
    FC_LINE,
    MITSUBISHI_LINE,
    _fcmaster,
    saved,
    sim_drive,
)
from tests.integration.test_params_commission import params as _params

FC_WRITES = {RequestAk.WRITE_WORD, RequestAk.WRITE_DWORD, RequestAk.WRITE_WORD_EEPROM,
             RequestAk.WRITE_DWORD_EEPROM}  # fmt: skip


async def params(server: PtyServer, protocol: str, verb: str, *args: str) -> tuple[int, str, str]:
    """``fcmaster params VERB`` on ``server``, with a reply deadline a busy machine keeps.

    What these tests judge is what is written, not how fast the drive answers: a reply the
    loaded test machine delivers late must not fail a backup.
    """
    return await _params(server, protocol, verb, "--timeout", "2", *args)


@dataclass
class Wire:
    """What the master sent: its bytes as written, and the frames the drive heard."""

    sent: bytearray = field(default_factory=bytearray)
    frames: list[bytes] = field(default_factory=list)


@contextmanager
def recorded(server: PtyServer, drive: object) -> Iterator[Wire]:
    """Record the master's bytes on ``server``'s line and the frames ``drive`` hears."""
    wire = Wire()
    line = server.line
    write, handle = line.write, drive.handle  # type: ignore[attr-defined]

    def on_line(data: bytes) -> None:
        wire.sent += data
        write(data)

    def heard(frame: bytes, now: float) -> bytes | None:
        wire.frames.append(frame)
        reply: bytes | None = handle(frame, now)
        return reply

    line.write = on_line  # type: ignore[method-assign]
    drive.handle = heard  # type: ignore[attr-defined]
    try:
        yield wire
    finally:
        line.write = write  # type: ignore[method-assign]
        drive.handle = handle  # type: ignore[attr-defined]


def fc_writes(wire: Wire) -> list[tuple[int, int]]:
    """(PNU, PWE) of every FC write request the drive heard."""
    telegrams = [decode_telegram(frame, from_drive=False) for frame in wire.frames]
    return [(t.pnu, t.pwe) for t in telegrams if t.ak in FC_WRITES]


def mitsubishi_writes(wire: Wire) -> list[tuple[int, int | None]]:
    """(instruction code, data) of every Mitsubishi parameter write the drive heard.

    Parameter writes are H80-HE3 (H80 + the parameter's number on its page); the page
    itself is chosen by writing HFF, which is not a setting.
    """
    requests = [decode_frame(frame) for frame in wire.frames]
    writes = [r for r in requests if isinstance(r, Request) and not r.is_read]
    return [(r.instruction, r.data) for r in writes if 0x80 <= r.instruction <= 0xE3]


def config_file(tmp_path: Path, port: str, protocol: str, address: int, max_hz: float) -> Path:
    path = tmp_path / "plant.yaml"
    drive = {"name": "pump-1", "address": address, "max_frequency_hz": max_hz}
    bus = {"name": "line1", "port": port, "protocol": protocol, "drives": [drive]}
    path.write_text(yaml.safe_dump({"buses": [bus]}))
    return path


async def test_fc_a_file_with_parameters_outside_the_set_puts_nothing_on_the_line(
    tmp_path: Path,
) -> None:
    backup = tmp_path / "drive1.yaml"
    async with commissioning.served(FC_LINE, [(1, DriveSettings())]) as server:
        fc = "danfoss-fc"
        code, _, err = await params(server, fc, "backup", "--address", "1", "-o", str(backup))
        assert code == 0, err
        data = saved(backup)
        data["parameters"]["3-42"].update(value=7.0, raw=700)  # a real change, to tempt it
        data["parameters"]["14-22"] = {"name": "Operation Mode", "value": 2.0, "raw": 2}
        data["parameters"]["1-20"] = {"name": "Motor Power [kW]", "value": 7.5, "raw": 750}
        backup.write_text(yaml.safe_dump(data, sort_keys=False))
        drive = sim_drive(server, 1, FcSimDrive)
        for force in ((), ("--force",)):  # --force never writes outside the set
            with recorded(server, drive) as wire:
                code, out, err = await params(
                    server, fc, "restore", "--address", "1", *force, str(backup)
                )
            assert code == 2, err + out
            assert "nothing was written" in err
            assert "14-22 (Operation Mode): not in the danfoss-fc parameter set" in err
            assert "1-20 (Motor Power [kW]): not in the danfoss-fc parameter set" in err
            assert "--force does not change this" in err
            assert "Traceback" not in err
            assert bytes(wire.sent) == b""  # the port was not even opened
        assert (drive.parameters[342], drive.parameters[120]) == (300, 550)


async def test_fc_a_bad_value_anywhere_is_refused_before_a_good_one_is_written(
    tmp_path: Path,
) -> None:
    backup = tmp_path / "drive1.yaml"
    async with commissioning.served(FC_LINE, [(1, DriveSettings())]) as server:
        fc = "danfoss-fc"
        code, _, err = await params(server, fc, "backup", "--address", "1", "-o", str(backup))
        assert code == 0, err
        data = saved(backup)
        data["parameters"]["4-14"].update(value=45.0, raw=450)  # earlier in the file: fine
        data["parameters"]["8-03"].update(value=-5.0, raw=-50)
        data["parameters"]["3-81"].update(value=0.0, raw=0)  # below the guide's 0.01 s
        backup.write_text(yaml.safe_dump(data, sort_keys=False))
        drive = sim_drive(server, 1, FcSimDrive)
        with recorded(server, drive) as wire:
            code, out, err = await params(server, fc, "restore", "--address", "1", str(backup))
        assert code == 2, err + out
        assert "8-03 (Control Word Timeout Time) = -5 s: cannot be written" in err
        assert "3-81 (Quick Stop Ramp Time) = 0 s: outside 0.01-3600 s" in err  # both at once
        assert bytes(wire.sent) == b""
        assert [drive.parameters[pnu] for pnu in (414, 803, 381)] == [650, 10, 300]


async def test_fc_a_limit_above_the_configured_maximum_is_written_only_when_forced(
    tmp_path: Path,
) -> None:
    backup = tmp_path / "drive1.yaml"
    async with commissioning.served(FC_LINE, [(1, DriveSettings())]) as server:
        fc = "danfoss-fc"
        code, _, err = await params(server, fc, "backup", "--address", "1", "-o", str(backup))
        assert code == 0, err
        data = saved(backup)
        data["parameters"]["4-14"].update(value=500.0, raw=5000)
        backup.write_text(yaml.safe_dump(data, sort_keys=False))
        plant = config_file(tmp_path, server.device, fc, 1, 50)
        drive = sim_drive(server, 1, FcSimDrive)
        restore = ("restore", "--address", "1", "--config", str(plant))
        with recorded(server, drive) as wire:
            code, out, err = await params(server, fc, *restore, str(backup))
        assert code == 2, err + out
        assert (
            "4-14 (Motor Speed High Limit [Hz]) = 500 Hz is above the drive's configured "
            "max_frequency_hz 50 (--force writes it anyway)"
        ) in err
        assert bytes(wire.sent) == b""
        assert drive.parameters[414] == 650

        with recorded(server, drive) as wire:
            code, out, err = await params(server, fc, *restore, "--force", str(backup))
        assert code == 0, err + out
        assert "max_frequency_hz 50: allowed by --force" in err
        assert fc_writes(wire) == [(414, 5000)]  # that one write, and nothing else
        assert drive.parameters[414] == 5000

        # Within the configured limit, no --force is needed.
        data["parameters"]["4-14"].update(value=45.0, raw=450)
        backup.write_text(yaml.safe_dump(data, sort_keys=False))
        with recorded(server, drive) as wire:
            code, out, err = await params(server, fc, *restore, str(backup))
        assert code == 0, err + out
        assert fc_writes(wire) == [(414, 450)]


async def test_mitsubishi_a_maximum_frequency_above_the_config_and_a_stray_parameter(
    tmp_path: Path,
) -> None:
    backup = tmp_path / "station3.yaml"
    async with commissioning.served(MITSUBISHI_LINE, [(3, DriveSettings())]) as server:
        mit = "mitsubishi"
        code, _, err = await params(server, mit, "backup", "--address", "3", "-o", str(backup))
        assert code == 0, err
        drive = sim_drive(server, 3, MitsubishiSimDrive)
        drive.parameters.set(1, 6000)  # Pr.1 = 60 Hz now; the file says 120 Hz
        plant = config_file(tmp_path, server.device, mit, 3, 60)
        restore = ("restore", "--address", "3", "--config", str(plant))
        with recorded(server, drive) as wire:
            code, out, err = await params(server, mit, *restore, str(backup))
        assert code == 2, err + out
        assert "Pr.1 (maximum frequency) = 120 Hz is above the drive's configured" in err
        assert bytes(wire.sent) == b""
        assert drive.parameters[1] == 6000

        data = saved(backup)
        data["parameters"]["Pr.30"] = {"name": "regenerative function selection", "value": 1.0}
        backup.write_text(yaml.safe_dump(data, sort_keys=False))
        with recorded(server, drive) as wire:
            code, out, err = await params(server, mit, *restore, "--force", str(backup))
        assert code == 2, err + out
        assert "Pr.30 (regenerative function selection): not in the mitsubishi parameter set" in err
        assert bytes(wire.sent) == b""

        del data["parameters"]["Pr.30"]
        backup.write_text(yaml.safe_dump(data, sort_keys=False))
        with recorded(server, drive) as wire:
            code, out, err = await params(server, mit, *restore, "--force", str(backup))
        assert code == 0, err + out
        assert mitsubishi_writes(wire) == [(0x81, 12000)]  # Pr.1, 120.00 Hz
        assert drive.parameters[1] == 12000


async def test_a_parameter_given_twice_in_the_file_is_refused(tmp_path: Path) -> None:
    backup = tmp_path / "drive1.yaml"
    async with commissioning.served(FC_LINE, [(1, DriveSettings())]) as server:
        fc = "danfoss-fc"
        code, _, err = await params(server, fc, "backup", "--address", "1", "-o", str(backup))
        assert code == 0, err
        text = backup.read_text()
        first = text.index("  3-42:")
        again = '  "3-42": {name: Ramp 1 Ramp Down Time, value: 9.0, unit: s, raw: 900}\n'
        backup.write_text(text[:first] + again + text[first:])
        drive = sim_drive(server, 1, FcSimDrive)
        with recorded(server, drive) as wire:
            code, out, err = await params(server, fc, "restore", "--address", "1", str(backup))
        assert code == 2, err + out
        assert "parameters.3-42: given twice" in err
        assert bytes(wire.sent) == b""
        assert drive.parameters[342] == 300


async def test_the_help_says_what_force_may_override_and_what_it_never_may() -> None:
    code, out, _ = await _fcmaster("params", "restore", "--help")
    assert code == 0
    text = " ".join(out.split())  # argparse wraps to the terminal's width
    assert "ceilings above the configured max_frequency_hz" in text
    assert "never anything outside the set (a factory reset, the operation mode)" in text
    assert "Nothing is written (exit 2)" in text


async def test_a_config_without_that_drive_or_of_another_protocol_is_refused(
    tmp_path: Path,
) -> None:
    backup = tmp_path / "drive1.yaml"
    backup.write_text(yaml.safe_dump(ParameterSet(protocol="danfoss-fc", address=1).to_dict()))
    port = str(tmp_path / "ttyUSB9")  # never opened: the file is judged first
    plant = config_file(tmp_path, port, "danfoss-fc", 2, 50)
    restore = ("params", "restore", "--port", port, "--config", str(plant), str(backup))
    code, _, err = await _fcmaster(*restore, "--address", "1")
    assert code == 2
    assert f"bus line1 in {plant} has no drive at address 1" in err
    code, _, err = await _fcmaster(*restore, "--address", "2", "--port", "/dev/ttyUSB7")
    assert code == 2
    assert f"no bus in {plant} is at /dev/ttyUSB7" in err
    plant = config_file(tmp_path, port, "mitsubishi", 2, 50)
    code, _, err = await _fcmaster(*restore, "--address", "2")
    assert code == 2
    assert "bus line1 in" in err
    assert "is mitsubishi; the line is danfoss-fc (--protocol)" in err
