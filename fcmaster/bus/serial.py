"""The serial transport: a local port or any pyserial URL.

pyserial opens and configures the port (termios, RS-485 mode). A local port (a UART, a USB
adapter, a pty) is then read and written on its file descriptor directly: the event loop's
reader callback does one non-blocking ``os.read`` straight into a buffer, and a request is
one ``os.write``. pyserial's own ``read`` and ``write`` would add a ``select()`` to each
(they implement timeouts), and pyserial-asyncio's reader callback goes through them. URLs
whose handler has a descriptor of its own (``socket://``) go through pyserial-asyncio-fast.
Handlers without one (``rfc2217://``, whose client keeps its own socket and reader thread,
and refuses the write timeout pyserial-asyncio sets) are read in a thread of their own that
hands each chunk to the loop. Either way a read waits on one future with one timer: no
StreamReader, no per-read task, so the hot path costs one wake-up per chunk delivered.

Pseudo-terminals refuse some termios changes a UART takes: once parity has been asked for,
every later reconfiguration of the pty fails with EINVAL. A pty carries no parity bits
anyway, so on a pty (and only there) the port is opened without parity; everything else is
the same code path as a real UART, and the character timing the master computes still uses
the configured format.
"""

from __future__ import annotations

import asyncio
import io
import os
import socket
import termios
import threading
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
from fcmaster.protocol.framing import Frame, Framer, Skipped

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


class _Receiver(asyncio.Protocol):
    """Collects received bytes and wakes the one reader waiting for them.

    A reader that hands over its framer (:meth:`SerialTransport.read_frame`) is woken only
    when the framer holds a whole piece (a frame, or bytes it skipped), an inter-character
    gap has passed, or the deadline: the chunks of one reply are fed to the framer right
    here, in the reader callback, so a reply costs one wake-up however it was split.
    """

    __slots__ = ("buffer", "framer", "gap_s", "lost", "piece", "received_at", "timer", "waiter")

    def __init__(self) -> None:
        self.buffer = bytearray()
        self.waiter: asyncio.Future[None] | None = None
        self.lost: Exception | None = None
        self.received_at = 0.0
        self.framer: Framer | None = None  # the waiting reader's, while it waits
        self.piece: Frame | Skipped | None = None  # what the framer cut out for it
        self.gap_s = 0.0
        self.timer: asyncio.TimerHandle | None = None  # the deadline's or the gap's

    def data_received(self, data: bytes) -> None:
        self.arrived(data, time.monotonic())  # the loop's and MonotonicClock's timebase

    def arrived(self, data: bytes, at: float) -> None:
        """``data`` arrived at monotonic time ``at`` (seen first in another thread)."""
        self.received_at = at
        framer = self.framer
        if framer is None:
            self.buffer += data
            waiter = self.waiter
            if waiter is not None and not waiter.done():
                waiter.set_result(None)
            return
        framer.feed(data)
        piece = framer.next_frame()
        if piece is not None:
            self.piece = piece
            self._wake()
        elif self.gap_s and framer.buffered:
            # An unfinished frame: look again one gap after its last byte. The timer is
            # moved only when it fires (see _on_gap), not for every chunk.
            timer = self.timer
            if timer is None or timer.when() > at + self.gap_s:
                if timer is not None:
                    timer.cancel()
                self.timer = asyncio.get_running_loop().call_at(at + self.gap_s, self.on_gap)

    def on_gap(self) -> None:
        """The gap timer fired: wake the reader unless bytes came since it was set."""
        due = self.received_at + self.gap_s
        loop = asyncio.get_running_loop()
        if due > loop.time() and self.waiter is not None:
            self.timer = loop.call_at(due, self.on_gap)
            return
        self.timer = None
        self._wake()

    def _wake(self) -> None:
        self.framer = None  # later bytes wait in the buffer
        waiter = self.waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def connection_lost(self, exc: Exception | None) -> None:
        self.lost = exc or ConnectionError("port closed")
        self.framer = None
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


class _ThreadPort:
    """A port whose pyserial handler has no descriptor (``rfc2217://``), read in a thread.

    The thread blocks in pyserial's ``read`` and hands each chunk, stamped with the time it
    was read, to the loop. Writes go straight to the handler: it sends them on a socket,
    and a request is a few dozen bytes, so the loop does not wait on them.
    """

    POLL_S = 0.1  # how often the reader thread looks whether the port is being closed

    def __init__(self, instance: serial.SerialBase, receiver: _Receiver) -> None:
        self._instance = instance
        self._receiver = receiver
        self._loop = asyncio.get_running_loop()
        self._closing = False
        self._thread = threading.Thread(
            target=self._read_loop, name=f"serial reader {instance.port}", daemon=True
        )
        self._thread.start()

    def _read_loop(self) -> None:
        instance, loop = self._instance, self._loop
        try:
            # Here, not on the loop: an RFC 2217 client waits for the server to agree.
            instance.timeout = self.POLL_S
        except Exception as exc:  # whatever ends the port is reported
            loop.call_soon_threadsafe(self._lost, exc)
            return
        while not self._closing:
            try:
                data = instance.read(1)
                if data and (waiting := instance.in_waiting):
                    data += instance.read(waiting)
            except Exception as exc:  # whatever ends the port is reported
                if not self._closing:
                    loop.call_soon_threadsafe(self._lost, exc)
                return
            if data:
                loop.call_soon_threadsafe(self._receiver.arrived, data, time.monotonic())

    def write(self, data: bytes) -> None:
        if self._closing:
            return
        try:
            self._instance.write(data)
        except (serial.SerialException, OSError) as exc:
            self._lost(exc)

    def is_closing(self) -> bool:
        return self._closing

    def close(self) -> None:
        if not self._closing:
            self._closing = True
            # pyserial's RFC 2217 client waits for its thread (and 0.3 s more) on close.
            threading.Thread(target=_close_quietly, args=(self._instance,), daemon=True).start()

    def _lost(self, exc: Exception) -> None:
        if not self._closing:
            self.close()
            self._receiver.connection_lost(exc)


class _UrlPort:
    """pyserial-asyncio's transport on a URL handler with a descriptor (``socket://``).

    Closing it also closes the handler's socket: pyserial's ``close`` leaves it open when
    the server has already shut the connection (its ``shutdown`` raises first).
    """

    def __init__(self, transport: _Port, instance: serial.SerialBase) -> None:
        self._transport = transport
        # Kept here: pyserial forgets it when its close fails, which may come first (the
        # transport closes itself when the server goes).
        self._socket: socket.socket | None = getattr(instance, "_socket", None)
        self.write = transport.write
        self.is_closing = transport.is_closing

    def close(self) -> None:
        self._transport.close()
        if self._socket is not None:
            self._socket.close()


def _close_quietly(instance: serial.SerialBase) -> None:
    # The RFC 2217 client leaves its socket open when the peer has shut it already.
    sock = getattr(instance, "_socket", None)
    try:
        instance.close()
    except Exception as exc:  # closing a port that is gone may fail
        log.debug("bus.close_failed", port=instance.port, error=str(exc))
    if sock is not None:
        sock.close()


def _has_descriptor(instance: serial.SerialBase) -> bool:
    try:
        instance.fileno()
    except (AttributeError, NotImplementedError, OSError, io.UnsupportedOperation):
        return False
    return True


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

    async def _drive(self, instance: serial.SerialBase, receiver: _Receiver) -> _Port:
        """The fastest way to drive the open ``instance`` that it supports."""
        # A local POSIX port has a descriptor; URL handlers (spy://, loop://, …) are other
        # classes, even where they subclass this one.
        if os.name == "posix" and type(instance) is serial.Serial:
            return _FdPort(instance, receiver)
        if not _has_descriptor(instance):
            return _ThreadPort(instance, receiver)
        try:
            transport, _ = await serial_asyncio_fast.connection_for_serial(
                asyncio.get_running_loop(), lambda: receiver, instance
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise PortError(f"cannot use {self.port}: {exc}") from exc
        return _UrlPort(transport, instance)

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

    async def read_frame(
        self, framer: Framer, deadline: float, gap_s: float
    ) -> Frame | Skipped | None:
        """The next piece ``framer`` cuts from the bytes received, waiting until ``deadline``.

        None: the deadline passed, or a gap of ``gap_s`` followed an unfinished frame (the
        caller tells them apart by the time). The bytes are fed to ``framer`` as they
        arrive, in the reader callback, and the caller is woken once, when a piece is whole:
        not for every chunk as :meth:`read` would. :attr:`received_at` is the arrival of
        the bytes that completed the piece.
        """
        receiver = self._receiver
        if receiver.buffer:
            framer.feed(bytes(receiver.buffer))
            receiver.buffer.clear()
        piece = framer.next_frame()
        if piece is not None:
            return piece
        if receiver.lost is not None:
            raise PortError(f"{self.port} was lost: {receiver.lost}")
        loop = asyncio.get_running_loop()
        waiter: asyncio.Future[None] = loop.create_future()
        receiver.waiter, receiver.framer, receiver.piece = waiter, framer, None
        receiver.gap_s = gap_s
        if framer.buffered:  # a frame begun in an earlier read: the gap runs from its bytes
            deadline = min(deadline, receiver.received_at + gap_s)
        timer = loop.call_at(deadline, _expire, waiter)
        try:
            await waiter
        finally:
            timer.cancel()
            if receiver.timer is not None:
                receiver.timer.cancel()
                receiver.timer = None
            receiver.waiter = receiver.framer = None
        piece, receiver.piece = receiver.piece, None
        if piece is None and receiver.lost is not None:
            raise PortError(f"{self.port} was lost: {receiver.lost}")
        return piece

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
