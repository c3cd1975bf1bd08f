"""The serial transport: a local port or any pyserial URL.

pyserial opens and configures the port (termios, RS-485 mode). A local port (a UART, a USB
adapter, a pty) is then read and written on its file descriptor directly: the event loop's
reader callback does one non-blocking ``os.read`` straight into a buffer, and a request is
one ``os.write``. pyserial's own ``read`` and ``write`` would add a ``select()`` to each
(they implement timeouts), and pyserial-asyncio's reader callback goes through them. Other
URLs (``socket://``, ``rfc2217://``, …) have no such descriptor and go through
pyserial-asyncio-fast. Either way a read waits on one future with one timer: no
StreamReader, no per-read task, so the hot path costs one wake-up per chunk the kernel
delivers.

Pseudo-terminals refuse some termios changes a UART takes: once parity has been asked for,
every later reconfiguration of the pty fails with EINVAL. A pty carries no parity bits
anyway, so on a pty (and only there) the port is opened without parity; everything else is
the same code path as a real UART, and the character timing the master computes still uses
the configured format.
"""

from __future__ import annotations

import asyncio
import os
import termios
import time
from typing import Any, Protocol

import serial
import serial.rs485
import serial_asyncio_fast
import structlog

from fcmaster.bus.adapter import Adapter, tune
from fcmaster.bus.open_errors import open_error
from fcmaster.bus.portlock import in_use_message, lock_refused
from fcmaster.errors import PortError, PortInUse, ReplyTimeout

log = structlog.get_logger("fcmaster.bus")

_PARITY = {"N": serial.PARITY_NONE, "E": serial.PARITY_EVEN, "O": serial.PARITY_ODD}
_PTY_MAJORS = range(136, 144)  # Unix98 pty slaves


def is_pty(port: str) -> bool:
    """Whether ``port`` names a pseudo-terminal slave (following links)."""
    try:
        return os.major(os.stat(port).st_rdev) in _PTY_MAJORS
    except (OSError, ValueError):
        return False


class _Receiver(asyncio.Protocol):
    """Collects received bytes and wakes the one reader waiting for them."""

    def __init__(self) -> None:
        self.buffer = bytearray()
        self.waiter: asyncio.Future[None] | None = None
        self.lost: Exception | None = None
        self.received_at = 0.0

    def data_received(self, data: bytes) -> None:
        self.received_at = time.monotonic()  # the loop's and MonotonicClock's timebase
        self.buffer += data
        waiter = self.waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def connection_lost(self, exc: Exception | None) -> None:
        self.lost = exc or ConnectionError("port closed")
        waiter = self.waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)


class _Port(Protocol):
    """What the transport needs of an open port, whichever way it is driven."""

    def write(self, data: bytes) -> None: ...
    def is_closing(self) -> bool: ...
    def close(self) -> None: ...


class _FdPort:
    """A local port driven on its file descriptor; pyserial only opened and configured it.

    pyserial opens ports non-blocking, so reads and writes never stall the loop. A write
    the kernel does not take whole (its output buffer is full) is finished by a writer
    callback, in order.
    """

    def __init__(self, instance: serial.Serial, receiver: _Receiver) -> None:
        self._instance = instance
        self._receiver = receiver
        self._fd = fd = instance.fileno()
        self._loop = asyncio.get_running_loop()
        self._unsent = b""
        self._closing = False
        self._loop.add_reader(fd, self._on_readable)

    def _on_readable(self) -> None:
        try:
            data = os.read(self._fd, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:  # EIO and the like: the adapter is gone
            self._lost(exc)
            return
        if data:
            self._receiver.data_received(data)
        else:  # readable but empty: the device went away
            self._lost(ConnectionError(f"{self._instance.port} returned no data"))

    def write(self, data: bytes) -> None:
        if self._closing:
            return
        if self._unsent:
            self._unsent += data
            return
        try:
            written = os.write(self._fd, data)
        except (BlockingIOError, InterruptedError):
            written = 0
        except OSError as exc:
            self._lost(exc)
            return
        if written < len(data):
            self._unsent = data[written:]
            self._loop.add_writer(self._fd, self._on_writable)

    def _on_writable(self) -> None:
        try:
            written = os.write(self._fd, self._unsent)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._lost(exc)
            return
        self._unsent = self._unsent[written:]
        if not self._unsent:
            self._loop.remove_writer(self._fd)

    def is_closing(self) -> bool:
        return self._closing

    def close(self) -> None:
        if not self._closing:
            self._closing = True
            self._loop.remove_reader(self._fd)
            self._loop.remove_writer(self._fd)
            self._instance.close()

    def _lost(self, exc: Exception) -> None:
        self.close()
        self._receiver.connection_lost(exc)


def _expire(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)


class SerialTransport:
    """A :class:`~fcmaster.bus.transport.Transport` on a serial port or pyserial URL."""

    def __init__(
        self,
        port: str,
        *,
        baudrate: int,
        parity: str = "E",
        stopbits: int = 1,
        databits: int = 8,
        rs485: bool = False,
    ) -> None:
        self.port = port
        self._settings: dict[str, Any] = {
            "baudrate": baudrate,
            "parity": _PARITY[parity],
            "stopbits": stopbits,
            "bytesize": databits,
        }
        self._rs485 = rs485
        self.adapter: Adapter | None = None  # the USB adapter behind a local port, once open
        self._receiver = _Receiver()
        self._transport: _Port | None = None
        self.in_use: PortInUse | None = None  # why the last open failed, if another has it

    async def open(self) -> None:
        """Open the port (in a worker thread: opening can block on some adapters)."""
        if self._transport is not None:
            return
        loop = asyncio.get_running_loop()
        self._receiver = receiver = _Receiver()
        transport: _Port
        try:
            if self.port.startswith("socket://"):
                transport, _ = await serial_asyncio_fast.create_serial_connection(
                    loop, lambda: receiver, self.port, **self._settings
                )
            else:
                instance = await loop.run_in_executor(None, self._open_serial)
                # A local POSIX port has a descriptor; URL handlers (spy://, loop://, …)
                # are other classes, even where they subclass this one.
                if os.name == "posix" and type(instance) is serial.Serial:
                    transport = _FdPort(instance, receiver)
                else:
                    transport, _ = await serial_asyncio_fast.connection_for_serial(
                        loop, lambda: receiver, instance
                    )
        except (serial.SerialException, OSError, ValueError, termios.error) as exc:
            if lock_refused(exc):  # another program has it: say who, and touch nothing
                self.in_use = PortInUse(in_use_message(self.port))
                raise self.in_use from exc
            raise PortError(open_error(self.port, exc)) from exc
        self.in_use = None
        self._transport = transport

    def _open_serial(self) -> serial.Serial:
        settings = self._settings
        if settings["parity"] != serial.PARITY_NONE and is_pty(self.port):
            # A pty refuses every later termios change once parity was asked for (even
            # pyserial-asyncio's own timeout=0), and carries no parity bits anyway.
            log.debug("bus.pty_parity_ignored", port=self.port, parity=settings["parity"])
            settings = {**settings, "parity": serial.PARITY_NONE}
        instance = serial.serial_for_url(
            self.port, do_not_open=True, timeout=0, exclusive=True, **settings
        )
        if self._rs485:
            instance.rs485_mode = serial.rs485.RS485Settings(
                rts_level_for_tx=True, rts_level_for_rx=False
            )
        instance.open()
        if os.name == "posix" and type(instance) is serial.Serial:
            self.adapter = tune(self.port, instance.fileno())  # once per open, not per read
        return instance

    async def close(self) -> None:
        """Close the port; safe when it is not open."""
        transport, self._transport = self._transport, None
        if transport is not None:
            transport.close()
            await asyncio.sleep(0)  # let the close callbacks run

    async def write(self, data: bytes) -> None:
        """Hand ``data`` to the port in one write."""
        transport = self._transport
        if transport is None or transport.is_closing() or self._receiver.lost is not None:
            raise PortError(f"{self.port} is not open: {self._receiver.lost or 'closed'}")
        transport.write(data)

    async def read(self, deadline: float) -> bytes:
        """Bytes received so far, waiting for some until ``deadline`` (loop time).

        The deadline is on the event loop's clock, which is MonotonicClock's timebase.
        """
        receiver = self._receiver
        if not receiver.buffer:
            if receiver.lost is not None:
                raise PortError(f"{self.port} was lost: {receiver.lost}")
            loop = asyncio.get_running_loop()
            waiter: asyncio.Future[None] = loop.create_future()
            receiver.waiter = waiter
            timer = loop.call_at(deadline, _expire, waiter)
            try:
                await waiter
            finally:
                timer.cancel()
                receiver.waiter = None
            if not receiver.buffer:
                if receiver.lost is not None:
                    raise PortError(f"{self.port} was lost: {receiver.lost}")
                raise ReplyTimeout(f"no reply on {self.port}")
        data = bytes(receiver.buffer)
        receiver.buffer.clear()
        return data

    @property
    def received_at(self) -> float:
        """When the port last delivered bytes (monotonic time)."""
        return self._receiver.received_at

    def discard_input(self) -> bytes:
        """Drop and return the bytes received but not read."""
        receiver = self._receiver
        if not receiver.buffer:
            return b""
        data = bytes(receiver.buffer)
        receiver.buffer.clear()
        return data
