"""The serial transport: a local port or any pyserial URL, through pyserial-asyncio-fast.

Bytes are delivered by the event loop's reader callback straight into a buffer, and a read
waits on one future with one timer: no StreamReader, no per-read task, so the hot path
costs one wake-up per chunk the kernel delivers.

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
from typing import Any

import serial
import serial.rs485
import serial_asyncio_fast
import structlog

from fcmaster.errors import PortError, ReplyTimeout

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

    def data_received(self, data: bytes) -> None:
        self.buffer += data
        waiter = self.waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def connection_lost(self, exc: Exception | None) -> None:
        self.lost = exc or ConnectionError("port closed")
        waiter = self.waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)


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
        self._receiver = _Receiver()
        self._transport: asyncio.Transport | None = None

    async def open(self) -> None:
        """Open the port (in a worker thread: opening can block on some adapters)."""
        if self._transport is not None:
            return
        loop = asyncio.get_running_loop()
        self._receiver = receiver = _Receiver()
        try:
            if self.port.startswith("socket://"):
                transport, _ = await serial_asyncio_fast.create_serial_connection(
                    loop, lambda: receiver, self.port, **self._settings
                )
            else:
                instance = await loop.run_in_executor(None, self._open_serial)
                transport, _ = await serial_asyncio_fast.connection_for_serial(
                    loop, lambda: receiver, instance
                )
        except (serial.SerialException, OSError, ValueError, termios.error) as exc:
            raise PortError(
                f"cannot open {self.port}: {exc} (check the device path, and that this user "
                "may use it, e.g. is in the dialout group)"
            ) from exc
        self._transport = transport

    def _open_serial(self) -> serial.Serial:
        settings = self._settings
        if settings["parity"] != serial.PARITY_NONE and is_pty(self.port):
            # A pty refuses every later termios change once parity was asked for (even
            # pyserial-asyncio's own timeout=0), and carries no parity bits anyway.
            log.debug("bus.pty_parity_ignored", port=self.port, parity=settings["parity"])
            settings = {**settings, "parity": serial.PARITY_NONE}
        instance = serial.serial_for_url(self.port, do_not_open=True, timeout=0, **settings)
        if self._rs485:
            instance.rs485_mode = serial.rs485.RS485Settings(
                rts_level_for_tx=True, rts_level_for_rx=False
            )
        instance.open()
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

    def discard_input(self) -> bytes:
        """Drop and return the bytes received but not read."""
        receiver = self._receiver
        if not receiver.buffer:
            return b""
        data = bytes(receiver.buffer)
        receiver.buffer.clear()
        return data
