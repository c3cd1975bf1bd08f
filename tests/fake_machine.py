"""A fake machine's serial devices: a sysfs tree and a /dev tree as Linux lays them out,
and the TIOCGSERIAL/TIOCSSERIAL flags of the drivers that answer them (or refuse)."""

from __future__ import annotations

import errno
import os
from pathlib import Path

from fcmaster.transport.usb import ASYNC_LOW_LATENCY, Machine

FTDI_BY_ID = "usb-FTDI_FT232R_USB_UART_A10K1234-if00-port0"
FTDI_BY_PATH = "pci-0000:00:14.0-usb-0:2:1.0-port0"
CH340_BY_ID = "usb-1a86_USB_Serial-if00-port0"


class FakeMachine(Machine):
    """A sysfs and /dev under ``root``; ``read_only`` latency files refuse writes (EACCES)."""

    def __init__(self, root: Path, *, read_only: bool = False) -> None:
        super().__init__(sys=root / "sys", dev=root / "dev")
        self.read_only = read_only
        self.written: list[tuple[str, int]] = []

    def add(
        self,
        name: str,
        driver: str,
        *,
        latency_ms: int | None = None,
        by_id: str | None = None,
        by_path: str | None = None,
        usb: bool = True,
    ) -> str:
        """A tty ``name`` on ``driver`` (a latency timer where given); its /dev path."""
        parent = "pci0000:00/0000:00:14.0/usb1/1-2/1-2:1.0" if usb else "platform/serial8250"
        device = self.sys / "devices" / parent / name
        device.mkdir(parents=True)
        bus = "usb-serial" if usb else "platform"
        drivers = self.sys / "bus" / bus / "drivers" / driver
        drivers.mkdir(parents=True, exist_ok=True)
        (device / "driver").symlink_to(drivers)
        tty = self.sys / "class" / "tty" / name
        tty.mkdir(parents=True)
        (tty / "device").symlink_to(device)
        if latency_ms is not None:
            (device / "latency_timer").write_text(f"{latency_ms}\n")
            devices = self.sys / "bus" / "usb-serial" / "devices"
            devices.mkdir(parents=True, exist_ok=True)
            (devices / name).symlink_to(device)
        self.dev.mkdir(parents=True, exist_ok=True)
        (self.dev / name).write_text("")
        for kind, link in (("by-id", by_id), ("by-path", by_path)):
            if link is not None:
                folder = self.dev / "serial" / kind
                folder.mkdir(parents=True, exist_ok=True)
                (folder / link).symlink_to(os.path.relpath(self.dev / name, folder))
        return str(self.dev / name)

    def add_virtual(self, name: str) -> None:
        """A tty with no device behind it (a virtual console)."""
        (self.sys / "class" / "tty" / name).mkdir(parents=True)

    def write_latency_ms(self, name: str, value: int) -> None:
        if self.read_only:
            raise PermissionError(errno.EACCES, "Permission denied")
        self.written.append((name, value))
        super().write_latency_ms(name, value)


class FtdiFlags:
    """ftdi_sio: ASYNC_LOW_LATENCY set through TIOCSSERIAL makes the latency timer 1 ms.

    ``honoured`` False: a driver that keeps the flag but not the timer (older kernels)."""

    def __init__(self, machine: FakeMachine, name: str, *, honoured: bool = True) -> None:
        self.machine = machine
        self.name = name
        self.honoured = honoured
        self.flags = 0x0040  # some other flag the driver had set, which must be kept
        self.sets: list[int] = []

    def get(self, fd: int) -> int:
        return self.flags

    def set(self, fd: int, flags: int) -> None:
        self.sets.append(flags)
        self.flags = flags
        if self.honoured and flags & ASYNC_LOW_LATENCY:
            self.machine.latency_file(self.name).write_text("1\n")


class RefusingFlags:
    """CH340, CP210x and others: TIOCSSERIAL (or TIOCGSERIAL) is refused."""

    def __init__(self) -> None:
        self.calls = 0

    def get(self, fd: int) -> int:
        self.calls += 1
        raise OSError(errno.ENOTTY, "Inappropriate ioctl for device")

    def set(self, fd: int, flags: int) -> None:
        self.calls += 1
        raise OSError(errno.EINVAL, "Invalid argument")
