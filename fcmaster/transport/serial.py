"""The serial transport: a local port or any pyserial URL.

pyserial opens and configures the port (termios, RS-485 mode). A local port (a UART, a USB
adapter, a pty) is then read and written on its file descriptor directly: the event loop's
reader callback does one non-blocking ``os.read`` straight into a buffer, and a request is
one ``os.write``. pyserial's own ``read`` and ``write`` would add a ``select()`` to each
(they implement timeouts), and pyserial-asyncio's reader callback goes through them. URLs
whose handler has a descriptor of its own (``socket://``) go through pyserial-asyncio-fast.
Handlers without one (``rfc2217://``, whose client keeps its own socket and reader thread,
and refuses the write timeout pyserial-asyncio sets) are read in a thread of their own that
hands each chunk to the loop. Either way what arrives goes to a
:class:`~fcmaster.transport.receiver.Receiver`: no StreamReader, no per-read task, and a reader
that hands over its framer is called once per reply, however it was split.

Arrivals are stamped and deadlines are read on the transport's clock (the master's), which
need not share the event loop's timebase.

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

from fcmaster.clock import Clock, MonotonicClock
from fcmaster.errors import PortError, PortInUse, ReplyTimeout
from fcmaster.protocol.framing import Framer
from fcmaster.transport.open_errors import open_error
from fcmaster.transport.portlock import in_use_message, lock_refused
from fcmaster.transport.ports import FdPort, Port, ThreadPort, UrlPort, has_descriptor
from fcmaster.transport.receiver import Handler, Piece, Receiver
from fcmaster.transport.usb import Adapter, tune

log = structlog.get_logger("fcmaster.bus")

_PARITY = {"N": serial.PARITY_NONE, "E": serial.PARITY_EVEN, "O": serial.PARITY_ODD}
_PTY_MAJORS = range(136, 144)  # Unix98 pty slaves
APPEAR_POLL_S = 0.05  # how often a missing device node is looked for while the line is down


def is_pty(port: str) -> bool:
    """Whether ``port`` names a pseudo-terminal slave (following links)."""
    try:
        return os.major(os.stat(port).st_rdev) in _PTY_MAJORS
    except (OSError, ValueError):
        return False


class SerialTransport:
    """A :class:`~fcmaster.transport.pipe.Transport` on a serial port or pyserial URL."""

    def __init__(
        self,
        port: str,
        *,
        baudrate: int,
        parity: str = "E",
        stopbits: int = 1,
        databits: int = 8,
        rs485: bool = False,
        clock: Clock | None = None,
    ) -> None:
        self.port = port
        # Arrivals are stamped and deadlines read on this clock (the master's).
        self.clock = clock or MonotonicClock()
        self._settings: dict[str, Any] = {
            "baudrate": baudrate,
            "parity": _PARITY[parity],
            "stopbits": stopbits,
            "bytesize": databits,
        }
        self._rs485 = rs485
        self.adapter: Adapter | None = None  # the USB adapter behind a local port, once open
        self._receiver = Receiver(self.clock)
        self._transport: Port | None = None
        self.in_use: PortInUse | None = None  # why the last open failed, if another has it

    async def open(self) -> None:
        """Open the port (in a worker thread: opening can block on some adapters)."""
        if self._transport is not None:
            return
        loop = asyncio.get_running_loop()
        self._receiver = receiver = Receiver(self.clock)
        transport: Port
        try:
            instance = await loop.run_in_executor(None, self._open_serial)
        except (serial.SerialException, OSError, ValueError, termios.error) as exc:
            if lock_refused(exc):  # another program has it: say who, and touch nothing
                self.in_use = PortInUse(in_use_message(self.port))
                raise self.in_use from exc
            raise PortError(open_error(self.port, exc)) from exc
        self.in_use = None
        try:
            transport = await self._drive(instance, receiver)
        except BaseException:
            instance.close()
            raise
        self._transport = transport

    async def _drive(self, instance: serial.SerialBase, receiver: Receiver) -> Port:
        """The fastest way to drive the open ``instance`` that it supports."""
        # A local POSIX port has a descriptor; URL handlers (spy://, loop://, …) are other
        # classes, even where they subclass this one.
        if os.name == "posix" and type(instance) is serial.Serial:
            return FdPort(instance, receiver)
        if not has_descriptor(instance):
            return ThreadPort(instance, receiver, self.clock.now)
        try:
            transport, _ = await serial_asyncio_fast.connection_for_serial(
                asyncio.get_running_loop(), lambda: receiver, instance
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise PortError(f"cannot use {self.port}: {exc}") from exc
        return UrlPort(transport, instance)

    def _open_serial(self) -> serial.SerialBase:
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

    async def appeared(self) -> None:
        """Return when the port's device node exists again; never for URLs or present nodes.

        The master waits on this beside its backoff after a failed open, so an adapter that
        is plugged back in is opened at once. The check runs only while the line is down.
        """
        # A stat of a /dev entry never blocks for long, and nothing signals a node appearing
        # without inotify: polling it while the line is down is the simple way.
        if "://" in self.port or os.path.exists(self.port):  # noqa: ASYNC240
            await asyncio.Event().wait()  # nothing to watch: the backoff decides
        while not os.path.exists(self.port):  # noqa: ASYNC110, ASYNC240
            await asyncio.sleep(APPEAR_POLL_S)

    async def close(self) -> None:
        """Close the port; safe when it is not open."""
        transport, self._transport = self._transport, None
        if transport is not None:
            transport.close()
            await asyncio.sleep(0)  # let the close callbacks run

    async def write(self, data: bytes) -> None:
        """Hand ``data`` to the port in one write."""
        self.write_now(data)

    def write_now(self, data: bytes) -> None:
        """:meth:`write`, from a callback: the port takes the bytes without waiting."""
        transport = self._transport
        if transport is None or transport.is_closing() or self._receiver.lost is not None:
            raise PortError(f"{self.port} is not open: {self._receiver.lost or 'closed'}")
        transport.write(data)

    async def read(self, deadline: float) -> bytes:
        """Bytes received so far, waiting for some until ``deadline`` (the clock's time)."""
        receiver = self._receiver
        if not receiver.buffer:
            if receiver.lost is not None:
                raise PortError(f"{self.port} was lost: {receiver.lost}")
            await receiver.wait_bytes(deadline)
            if not receiver.buffer:
                if receiver.lost is not None:
                    raise PortError(f"{self.port} was lost: {receiver.lost}")
                raise ReplyTimeout(f"no reply on {self.port}")
        data = bytes(receiver.buffer)
        receiver.buffer.clear()
        return data

    def watch_frame(self, framer: Framer, deadline: float, gap_s: float, handler: Handler) -> Piece:
        """Feed ``framer`` in the reader callback; ``handler`` gets the next whole piece.

        The bytes are fed to ``framer`` as they arrive, and ``handler`` is called once, when
        a piece is whole, or with None when ``deadline`` passed or a gap of ``gap_s``
        followed an unfinished frame (the caller tells them apart by the time): not a wake-up
        for every chunk as :meth:`read` would be. :attr:`received_at` is then the arrival of
        the bytes that completed the piece. A piece whole already is returned, and
        ``handler`` is not called (see :meth:`Receiver.watch`). The caller calls
        :meth:`check_open` when given None.
        """
        return self._receiver.watch(framer, deadline, gap_s, handler)

    def unwatch(self) -> None:
        """Stop :meth:`watch_frame` (its handler is not called)."""
        self._receiver.unwatch()

    def check_open(self) -> None:
        """Raise PortError if the port was lost."""
        if self._receiver.lost is not None:
            raise PortError(f"{self.port} was lost: {self._receiver.lost}")

    @property
    def framing(self) -> SerialTransport:
        """This transport frames in its reader callback and writes from callbacks."""
        return self

    @property
    def received_at(self) -> float:
        """When the port last delivered bytes (the clock's time)."""
        return self._receiver.received_at

    def discard_input(self) -> bytes:
        """Drop and return the bytes received but not read."""
        receiver = self._receiver
        if not receiver.buffer:
            return b""
        data = bytes(receiver.buffer)
        receiver.buffer.clear()
        return data
