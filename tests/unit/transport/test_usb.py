"""USB adapters: found behind their stable names, asked for low latency, warned about.

Every case runs against a fake sysfs and /dev tree (tests/fake_machine.py) and a fake
TIOCGSERIAL/TIOCSSERIAL layer that behaves as the named driver does.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from structlog.testing import capture_logs

from fcmaster.transport.usb import (
    ASYNC_LOW_LATENCY,
    UDEV_RULE,
    Adapter,
    list_adapters,
    tune,
)
from tests.fake_machine import (
    CH340_BY_ID,
    FTDI_BY_ID,
    FTDI_BY_PATH,
    FakeMachine,
    FtdiFlags,
    RefusingFlags,
)

FD = 7  # the fakes never use it


def ftdi(tmp_path: Path, *, read_only: bool = False) -> FakeMachine:
    machine = FakeMachine(tmp_path, read_only=read_only)
    machine.add("ttyUSB0", "ftdi_sio", latency_ms=16, by_id=FTDI_BY_ID, by_path=FTDI_BY_PATH)
    return machine


def test_an_ftdi_adapter_named_by_id_is_set_to_1_ms_through_the_ioctl(tmp_path: Path) -> None:
    machine = ftdi(tmp_path, read_only=True)
    flags = FtdiFlags(machine, "ttyUSB0")
    port = str(machine.dev / "serial" / "by-id" / FTDI_BY_ID)
    with capture_logs() as logs:
        adapter = tune(port, FD, machine=machine, flags=flags)
    assert adapter == Adapter(
        device=str(machine.dev / "ttyUSB0"),
        driver="ftdi_sio",
        by_id=port,
        by_path=str(machine.dev / "serial" / "by-path" / FTDI_BY_PATH),
        latency_ms=1,
        low_latency=True,
    )
    assert flags.sets == [0x0040 | ASYNC_LOW_LATENCY]  # the driver's other flags kept
    assert not [e for e in logs if e["log_level"] == "warning"]


def test_where_the_ioctl_is_refused_the_sysfs_file_is_written(tmp_path: Path) -> None:
    machine = ftdi(tmp_path)
    adapter = tune(str(machine.dev / "ttyUSB0"), FD, machine=machine, flags=RefusingFlags())
    assert adapter is not None
    assert machine.written == [("ttyUSB0", 1)]
    assert machine.latency_file("ttyUSB0").read_text() == "1\n"
    assert adapter.latency_ms == 1  # read back
    assert adapter.low_latency is None  # the driver has no such flag to report


def test_a_timer_that_stays_high_is_warned_about_with_its_cost_and_the_fix(
    tmp_path: Path,
) -> None:
    machine = ftdi(tmp_path, read_only=True)
    flags = FtdiFlags(machine, "ttyUSB0", honoured=False)  # flag kept, timer not changed
    with capture_logs() as logs:
        adapter = tune(str(machine.dev / "ttyUSB0"), FD, machine=machine, flags=flags)
    assert adapter is not None
    assert adapter.latency_ms == 16
    assert adapter.low_latency is True
    [warning] = [e for e in logs if e["log_level"] == "warning"]
    assert warning["event"] == "bus.adapter_latency_high"
    assert warning["latency_ms"] == 16
    assert warning["max_transactions_per_s"] == 62  # 1000 ms / 16 ms
    assert UDEV_RULE in warning["fix"]
    assert 'ATTR{latency_timer}="1"' in warning["fix"]


def test_a_ch340_has_no_timer_and_refuses_the_ioctl_quietly(tmp_path: Path) -> None:
    machine = FakeMachine(tmp_path)
    device = machine.add("ttyUSB1", "ch341-uart", by_id=CH340_BY_ID)
    flags = RefusingFlags()
    with capture_logs() as logs:
        adapter = tune(device, FD, machine=machine, flags=flags)
    assert adapter is not None
    assert flags.calls == 1
    assert (adapter.driver, adapter.latency_ms, adapter.low_latency) == ("ch341-uart", None, None)
    assert adapter.by_id == str(machine.dev / "serial" / "by-id" / CH340_BY_ID)
    assert machine.written == []
    assert not [e for e in logs if e["log_level"] == "warning"]


def test_a_port_sysfs_does_not_know_is_left_alone(tmp_path: Path) -> None:
    machine = ftdi(tmp_path)
    flags = RefusingFlags()
    assert tune("/dev/pts/3", FD, machine=machine, flags=flags) is None
    assert flags.calls == 0


def test_a_boards_own_uart_is_described_but_not_touched(tmp_path: Path) -> None:
    machine = FakeMachine(tmp_path)
    device = machine.add("ttyAMA0", "uart-pl011", usb=False)
    flags = RefusingFlags()
    adapter = tune(device, FD, machine=machine, flags=flags)
    assert adapter is not None
    assert (adapter.driver, adapter.latency_ms) == ("uart-pl011", None)
    assert flags.calls == 0


def test_adapters_are_listed_with_their_stable_names_and_onboard_uarts_left_out(
    tmp_path: Path,
) -> None:
    machine = ftdi(tmp_path)
    machine.add("ttyUSB1", "ch341-uart", by_id=CH340_BY_ID)
    machine.add("ttyS0", "serial8250", usb=False)  # listed by the kernel, fitted or not
    machine.add("ttyAMA0", "uart-pl011", usb=False)  # a board's own UART: a real port
    machine.add_virtual("tty1")
    listed = {a.device.rpartition("/")[2]: a for a in list_adapters(machine)}
    assert sorted(listed) == ["ttyAMA0", "ttyUSB0", "ttyUSB1"]
    assert listed["ttyUSB0"].stable_name == listed["ttyUSB0"].by_id
    assert listed["ttyUSB0"].latency_ms == 16  # listing never changes anything
    assert listed["ttyUSB1"].latency_ms is None
    assert listed["ttyAMA0"].stable_name is None
    assert machine.written == []


def test_a_machine_without_sysfs_lists_nothing(tmp_path: Path) -> None:
    assert list_adapters(FakeMachine(tmp_path / "none")) == []


@pytest.mark.parametrize("name", ["ttyUSB0"])
def test_the_json_shape(tmp_path: Path, name: str) -> None:
    machine = ftdi(tmp_path)
    assert machine.adapter(name).to_json() == {
        "device": str(machine.dev / name),
        "driver": "ftdi_sio",
        "by_id": str(machine.dev / "serial" / "by-id" / FTDI_BY_ID),
        "by_path": str(machine.dev / "serial" / "by-path" / FTDI_BY_PATH),
        "latency_ms": 16,
    }
