"""`fcmaster ports` and `check`'s warning about kernel port names, on a fake machine."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from fcmaster.subcommands import daemon, ports
from fcmaster.transport.usb import Machine
from tests.fake_machine import CH340_BY_ID, FTDI_BY_ID, FTDI_BY_PATH, FakeMachine

CONFIG = """
buses:
  - name: north
    port: {north}
    drives: [{{name: pump-1, address: 1}}]
  - name: south
    port: {south}
    drives: [{{name: fan-1, address: 2}}]
  - name: demo
    port: sim://demo
    drives: [{{name: fan-2, address: 3}}]
"""


@pytest.fixture
def machine(tmp_path: Path) -> FakeMachine:
    machine = FakeMachine(tmp_path / "root")
    machine.add("ttyUSB0", "ftdi_sio", latency_ms=16, by_id=FTDI_BY_ID, by_path=FTDI_BY_PATH)
    machine.add("ttyUSB1", "ch341-uart", by_id=CH340_BY_ID)
    return machine


def config(tmp_path: Path, north: str, south: str) -> Path:
    path = tmp_path / "plant.yaml"
    path.write_text(CONFIG.format(north=north, south=south))
    return path


def test_ports_lists_adapters_and_the_bus_using_each(tmp_path: Path, machine: FakeMachine) -> None:
    by_id = str(machine.dev / "serial" / "by-id" / FTDI_BY_ID)
    plant = config(tmp_path, north=by_id, south=str(machine.dev / "ttyUSB7"))
    out = io.StringIO()
    assert ports.run(plant, as_json=True, machine=machine, out=out) == 0
    listed = json.loads(out.getvalue())
    assert listed == {
        "adapters": [
            {
                "device": str(machine.dev / "ttyUSB0"),
                "driver": "ftdi_sio",
                "by_id": by_id,
                "by_path": str(machine.dev / "serial" / "by-path" / FTDI_BY_PATH),
                "latency_ms": 16,
                "used_by": ["north"],
            },
            {
                "device": str(machine.dev / "ttyUSB1"),
                "driver": "ch341-uart",
                "by_id": str(machine.dev / "serial" / "by-id" / CH340_BY_ID),
                "by_path": None,
                "latency_ms": None,
                "used_by": [],
            },
        ],
        "missing": [{"bus": "south", "port": str(machine.dev / "ttyUSB7")}],
    }


def test_ports_as_text(tmp_path: Path, machine: FakeMachine) -> None:
    plant = config(tmp_path, north=str(machine.dev / "ttyUSB1"), south=str(machine.dev / "none"))
    out = io.StringIO()
    assert ports.run(plant, as_json=False, machine=machine, out=out) == 0
    text = out.getvalue().splitlines()
    assert text[0] == (
        f"{machine.dev / 'ttyUSB0'}  ftdi_sio  latency 16 ms "
        "(fcmaster asks for 1 ms when it opens the port)"
    )
    assert text[1].split() == ["by-id", str(machine.dev / "serial" / "by-id" / FTDI_BY_ID)]
    assert text[2].split()[0] == "by-path"
    assert text[3].strip() == "not in the config"
    assert text[4] == f"{machine.dev / 'ttyUSB1'}  ch341-uart  no latency timer"
    assert text[6].strip() == "used by north"
    assert text[7] == f"bus south: {machine.dev / 'none'} is on no adapter of this machine"


def test_ports_on_a_machine_without_adapters(tmp_path: Path) -> None:
    out = io.StringIO()
    assert ports.run(None, as_json=False, machine=FakeMachine(tmp_path), out=out) == 0
    assert out.getvalue() == "no serial adapters found\n"


def test_check_warns_about_a_kernel_name_that_has_a_stable_one(
    tmp_path: Path, machine: FakeMachine, capsys: pytest.CaptureFixture[str]
) -> None:
    # ttyUSB0 has a by-id name; ttyUSB1's adapter is named by id in the config already.
    plant = config(
        tmp_path,
        north=str(machine.dev / "ttyUSB0"),
        south=str(machine.dev / "serial" / "by-id" / CH340_BY_ID),
    )
    assert daemon.check(plant, machine=machine) == 0
    warnings = [row for row in capsys.readouterr().out.splitlines() if "warning" in row]
    assert warnings == [
        f"  warning: north: {machine.dev / 'ttyUSB0'} may name another adapter after a reboot "
        f"or replug; use {machine.dev / 'serial' / 'by-id' / FTDI_BY_ID}"
    ]


def test_check_is_quiet_about_stable_names(
    tmp_path: Path, machine: FakeMachine, capsys: pytest.CaptureFixture[str]
) -> None:
    plant = config(
        tmp_path,
        north=str(machine.dev / "serial" / "by-path" / FTDI_BY_PATH),
        south=str(machine.dev / "serial" / "by-id" / CH340_BY_ID),
    )
    assert daemon.check(plant, machine=machine) == 0
    assert "warning" not in capsys.readouterr().out


def test_a_uart_behind_a_serial_base_port_is_named_by_its_own_driver(tmp_path: Path) -> None:
    # Linux 6.2+: ttyS0 → the serial-base "port" device, whose parent's parent is the UART.
    sysfs = tmp_path / "sys"
    uart = sysfs / "devices" / "pnp0" / "00:00"
    port = uart / "00:00:0" / "00:00:0.0"
    port.mkdir(parents=True)
    for bus, driver, device in (("serial-base", "port", port), ("pnp", "serial", uart)):
        (sysfs / "bus" / bus / "drivers" / driver).mkdir(parents=True)
        (device / "driver").symlink_to(sysfs / "bus" / bus / "drivers" / driver)
    (sysfs / "class" / "tty" / "ttyS0").mkdir(parents=True)
    (sysfs / "class" / "tty" / "ttyS0" / "device").symlink_to(port)
    assert Machine(sys=sysfs, dev=tmp_path / "dev").driver("ttyS0") == "serial"


def test_fcmaster_ports_json_on_this_machine() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "fcmaster", "ports", "--json"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    listed = json.loads(done.stdout)["adapters"]
    assert all(os.path.exists(entry["device"]) for entry in listed)
