"""USB serial adapters: what a port is, and asking it for low latency.

Theory of operation
-------------------
An FTDI adapter (the usual RS-485 dongle) holds received bytes until its buffer fills or its
*latency timer* runs out: 16 ms by default on Linux since 4.10. A drive's short reply then
reaches the host up to 16 ms late, every time, which caps a line at about 60 transactions a
second whatever its baud rate. Low latency is opt-in: the ``ASYNC_LOW_LATENCY`` flag of
``TIOCSSERIAL`` (ftdi_sio turns it into a 1 ms timer) or writing the sysfs file
``/sys/bus/usb-serial/devices/ttyUSBn/latency_timer`` (root, or a udev rule). CH340 and
CP210x adapters have no such timer, and some drivers refuse the ioctl.

:func:`tune` runs once when a local port opens (never per transaction): it finds the tty
behind the path (``/dev/serial/by-id/…`` links resolved), reads its driver and latency timer
from sysfs, asks for low latency both ways, reads the timer back and logs a warning with the
cost and the udev rule when it stays high. :func:`list_adapters` lists the machine's serial
adapters for ``fcmaster ports``. Both read sysfs and ``/dev`` under roots given to them, and
the ioctl goes through an injected :class:`SerialFlags`, so tests use a fake tree and a fake
driver.
"""

from __future__ import annotations

import array
import fcntl
import os
import termios
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Protocol

import structlog

log = structlog.get_logger("fcmaster.bus")

ASYNC_LOW_LATENCY: Final = 1 << 13  # linux/tty_flags.h
_TIOCGSERIAL: Final = getattr(termios, "TIOCGSERIAL", 0x541E)
_TIOCSSERIAL: Final = getattr(termios, "TIOCSSERIAL", 0x541F)
_FLAGS_INDEX: Final = 4  # struct serial_struct: type, line, port, irq, flags, …
LOW_LATENCY_MS: Final = 1
UDEV_RULE: Final = (
    'ACTION=="add", SUBSYSTEM=="usb-serial", DRIVER=="ftdi_sio", ATTR{latency_timer}="1"'
)
UDEV_FILE: Final = "/etc/udev/rules.d/99-fcmaster-low-latency.rules"
# Onboard 16550 UARTs: the kernel lists every possible one (ttyS0-31) whether fitted or not.
_NOT_ADAPTERS: Final = frozenset({"serial8250"})


class SerialFlags(Protocol):
    """The TIOCGSERIAL/TIOCSSERIAL flags of an open port (OSError where a driver refuses)."""

    def get(self, fd: int) -> int:
        """The port's flags."""

    def set(self, fd: int, flags: int) -> None:
        """Set the port's flags."""


class IoctlSerialFlags:
    """The real ioctls; ``struct serial_struct`` is read and written back whole."""

    def get(self, fd: int) -> int:
        """The port's flags (TIOCGSERIAL)."""
        return int(self._read(fd)[_FLAGS_INDEX])

    def set(self, fd: int, flags: int) -> None:
        """Set the port's flags (TIOCSSERIAL), everything else as it was."""
        buffer = self._read(fd)
        buffer[_FLAGS_INDEX] = flags
        fcntl.ioctl(fd, _TIOCSSERIAL, buffer)

    @staticmethod
    def _read(fd: int) -> array.array[int]:
        buffer = array.array("i", [0] * 32)  # larger than serial_struct on every ABI
        fcntl.ioctl(fd, _TIOCGSERIAL, buffer, True)
        return buffer


@dataclass(slots=True, frozen=True, kw_only=True)
class Adapter:
    """One serial adapter as the machine names it."""

    device: str  # /dev/ttyUSB0
    driver: str | None  # ftdi_sio, ch341-uart, cp210x, cdc_acm, …
    by_id: str | None  # /dev/serial/by-id/… (stable while the adapter is the same one)
    by_path: str | None  # /dev/serial/by-path/… (stable while it is in the same USB socket)
    latency_ms: int | None  # the latency timer; None where the adapter has none
    low_latency: bool | None = None  # ASYNC_LOW_LATENCY as read back (None: not asked)

    @property
    def stable_name(self) -> str | None:
        """The name to put in a config: by-id, else by-path."""
        return self.by_id or self.by_path

    def to_json(self) -> dict[str, Any]:
        """The public JSON shape (``/api/v1/buses`` ``adapter``, ``fcmaster ports --json``)."""
        return {
            "device": self.device,
            "driver": self.driver,
            "by_id": self.by_id,
            "by_path": self.by_path,
            "latency_ms": self.latency_ms,
        }


class Machine:
    """Where to read the machine's devices: the roots of sysfs and /dev (tests: a fake tree)."""

    def __init__(self, *, sys: Path = Path("/sys"), dev: Path = Path("/dev")) -> None:
        self.sys = sys
        self.dev = dev

    def tty_name(self, port: str) -> str | None:
        """The kernel's name for the tty behind ``port`` (links followed), if it has one."""
        name = os.path.basename(os.path.realpath(port))
        return name if (self.sys / "class" / "tty" / name / "device").exists() else None

    def is_usb(self, name: str) -> bool:
        """Whether tty ``name`` hangs on a USB device (an adapter, not a board's UART)."""
        device = os.path.realpath(self.sys / "class" / "tty" / name / "device")
        return any(part.startswith("usb") for part in Path(device).parts)

    def driver(self, name: str) -> str | None:
        """The kernel driver of tty ``name`` (ftdi_sio, …), if sysfs names one."""
        # Since Linux 6.2 a UART's tty hangs on a "port" device of the serial-base bus, whose
        # driver says nothing: the port's own driver is further up.
        device = Path(os.path.realpath(self.sys / "class" / "tty" / name / "device"))
        for _ in range(3):
            link = device / "driver"
            if not link.is_symlink():
                return None
            target = os.path.realpath(link)
            if os.path.basename(os.path.dirname(os.path.dirname(target))) != "serial-base":
                return os.path.basename(target)
            device = device.parent.parent  # port device → serial-base controller → hardware
        return None

    def latency_file(self, name: str) -> Path:
        """Where a USB serial driver keeps tty ``name``'s latency timer, in ms."""
        return self.sys / "bus" / "usb-serial" / "devices" / name / "latency_timer"

    def latency_ms(self, name: str) -> int | None:
        """Tty ``name``'s latency timer; None where it has none."""
        try:
            return int(self.latency_file(name).read_text().strip())
        except (OSError, ValueError):
            return None

    def write_latency_ms(self, name: str, value: int) -> None:
        """Set the latency timer; OSError where this user may not (only root, by default)."""
        self.latency_file(name).write_text(f"{value}\n")

    def links(self, kind: str, name: str) -> str | None:
        """The ``/dev/serial/<kind>/…`` link that leads to tty ``name`` (first by name)."""
        folder = self.dev / "serial" / kind
        try:
            entries = sorted(folder.iterdir())
        except OSError:
            return None
        for entry in entries:
            if entry.is_symlink() and os.path.basename(os.path.realpath(entry)) == name:
                return str(entry)
        return None

    def adapter(self, name: str, *, low_latency: bool | None = None) -> Adapter:
        """What the machine says about tty ``name`` now."""
        return Adapter(
            device=str(self.dev / name),
            driver=self.driver(name),
            by_id=self.links("by-id", name),
            by_path=self.links("by-path", name),
            latency_ms=self.latency_ms(name),
            low_latency=low_latency,
        )


def list_adapters(machine: Machine | None = None) -> list[Adapter]:
    """The machine's serial adapters (USB and other), onboard 8250 UARTs left out."""
    machine = machine or Machine()
    try:
        names = sorted(entry.name for entry in (machine.sys / "class" / "tty").iterdir())
    except OSError:
        return []
    adapters = []
    for name in names:
        if not (machine.sys / "class" / "tty" / name / "device").exists():
            continue  # virtual terminals, ptys, the console
        adapter = machine.adapter(name)
        if adapter.driver not in _NOT_ADAPTERS or adapter.stable_name:
            adapters.append(adapter)
    return adapters


def tune(
    port: str, fd: int, *, machine: Machine | None = None, flags: SerialFlags | None = None
) -> Adapter | None:
    """Ask the adapter behind the open ``port`` (descriptor ``fd``) for low latency.

    Returns what it is afterwards, or None when ``port`` is no tty sysfs knows (a pty). A
    port that is not on USB (a board's UART) is described but left as it is. Never raises
    for a driver that refuses: it is logged.
    """
    machine = machine or Machine()
    name = machine.tty_name(port)
    if name is None:
        return None
    if not machine.is_usb(name):
        return machine.adapter(name)  # a board's UART: no latency timer to ask about
    flags = flags or IoctlSerialFlags()
    low = _ask_low_latency(port, fd, flags)
    latency = machine.latency_ms(name)
    if latency is not None and latency > LOW_LATENCY_MS:
        try:
            machine.write_latency_ms(name, LOW_LATENCY_MS)
        except OSError as exc:
            log.debug("bus.adapter_latency_not_writable", port=port, error=exc.strerror or exc)
    adapter = machine.adapter(name, low_latency=low)
    if adapter.latency_ms is not None and adapter.latency_ms > LOW_LATENCY_MS:
        log.warning(
            "bus.adapter_latency_high",
            port=port,
            device=adapter.device,
            driver=adapter.driver,
            latency_ms=adapter.latency_ms,
            max_transactions_per_s=max_transactions_per_s(adapter.latency_ms),
            fix=f"as root: echo '{UDEV_RULE}' > {UDEV_FILE}; then replug the adapter",
        )
    else:
        log.info("bus.adapter_found", port=port, **adapter.to_json())
    return adapter


def max_transactions_per_s(latency_ms: int) -> int:
    """The most short request-reply exchanges a second when each reply waits out the timer."""
    return int(1000 / latency_ms) if latency_ms > 0 else 0


def _ask_low_latency(port: str, fd: int, flags: SerialFlags) -> bool | None:
    """Set ASYNC_LOW_LATENCY; whether it is set now (None: the driver has no such flags)."""
    try:
        current = flags.get(fd)
        if not current & ASYNC_LOW_LATENCY:
            flags.set(fd, current | ASYNC_LOW_LATENCY)
            current = flags.get(fd)
    except OSError as exc:  # CH340, CP210x and others refuse TIOCSSERIAL (or TIOCGSERIAL)
        log.debug("bus.adapter_low_latency_refused", port=port, error=exc.strerror or str(exc))
        return None
    return bool(current & ASYNC_LOW_LATENCY)
