"""The ways a serial transport drives an open pyserial port (see :mod:`fcmaster.transport.serial`).

A local POSIX port is read and written on its descriptor (:class:`FdPort`); a URL handler
with a descriptor of its own (``socket://``) goes through pyserial-asyncio-fast
(:class:`UrlPort`); one without (``rfc2217://``) is read in a thread (:class:`ThreadPort`).
Each hands what it receives to a :class:`Receiving` and reports the port's loss to it.
"""

from __future__ import annotations

import asyncio
import io
import os
import socket
import threading
from collections.abc import Callable
from typing import Protocol

import serial
import structlog

log = structlog.get_logger("fcmaster.bus")


class Receiving(Protocol):
    """Where a port hands what it receives."""

    def data_received(self, data: bytes) -> None:
        """Bytes read on the loop, just now."""

    def arrived(self, data: bytes, at: float) -> None:
        """Bytes read in another thread at clock time ``at``."""

    def connection_lost(self, exc: Exception | None) -> None:
        """The port is gone."""


class Port(Protocol):
    """What the transport needs of an open port, whichever way it is driven."""

    def write(self, data: bytes) -> None:
        """Send ``data``; never waits."""

    def is_closing(self) -> bool:
        """Whether the port is closed or closing."""
        ...

    def close(self) -> None:
        """Close the port."""


class FdPort:
    """A local port driven on its file descriptor; pyserial only opened and configured it.

    pyserial opens ports non-blocking, so reads and writes never stall the loop. A write
    the kernel does not take whole (its output buffer is full) is finished by a writer
    callback, in order.
    """

    def __init__(self, instance: serial.Serial, receiver: Receiving) -> None:
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
        """Send ``data``; never waits."""
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
        """Whether the port is closed or closing."""
        return self._closing

    def close(self) -> None:
        """Close the port."""
        if not self._closing:
            self._closing = True
            self._loop.remove_reader(self._fd)
            self._loop.remove_writer(self._fd)
            self._instance.close()

    def _lost(self, exc: Exception) -> None:
        self.close()
        self._receiver.connection_lost(exc)


class ThreadPort:
    """A port whose pyserial handler has no descriptor (``rfc2217://``), read in a thread.

    The thread blocks in pyserial's ``read`` and hands each chunk, stamped with the time it
    was read, to the loop. Writes go straight to the handler: it sends them on a socket,
    and a request is a few dozen bytes, so the loop does not wait on them.
    """

    POLL_S = 0.1  # how often the reader thread looks whether the port is being closed

    def __init__(
        self, instance: serial.SerialBase, receiver: Receiving, now: Callable[[], float]
    ) -> None:
        self._instance = instance
        self._receiver = receiver
        self._now = now  # the transport's clock: a chunk is stamped when the thread read it
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
                loop.call_soon_threadsafe(self._receiver.arrived, data, self._now())

    def write(self, data: bytes) -> None:
        """Send ``data``; never waits."""
        if self._closing:
            return
        try:
            self._instance.write(data)
        except (serial.SerialException, OSError) as exc:
            self._lost(exc)

    def is_closing(self) -> bool:
        """Whether the port is closed or closing."""
        return self._closing

    def close(self) -> None:
        """Close the port."""
        if not self._closing:
            self._closing = True
            # pyserial's RFC 2217 client waits for its thread (and 0.3 s more) on close.
            threading.Thread(target=close_quietly, args=(self._instance,), daemon=True).start()

    def _lost(self, exc: Exception) -> None:
        if not self._closing:
            self.close()
            self._receiver.connection_lost(exc)


class UrlPort:
    """pyserial-asyncio's transport on a URL handler with a descriptor (``socket://``).

    Closing it also closes the handler's socket: pyserial's ``close`` leaves it open when
    the server has already shut the connection (its ``shutdown`` raises first).
    """

    def __init__(self, transport: Port, instance: serial.SerialBase) -> None:
        self._transport = transport
        # Kept here: pyserial forgets it when its close fails, which may come first (the
        # transport closes itself when the server goes).
        self._socket: socket.socket | None = getattr(instance, "_socket", None)
        self.write = transport.write
        self.is_closing = transport.is_closing

    def close(self) -> None:
        """Close the port."""
        self._transport.close()
        if self._socket is not None:
            self._socket.close()


def close_quietly(instance: serial.SerialBase) -> None:
    """Close ``instance`` and its socket, logging what fails."""
    # The RFC 2217 client leaves its socket open when the peer has shut it already.
    sock = getattr(instance, "_socket", None)
    try:
        instance.close()
    except Exception as exc:  # closing a port that is gone may fail
        log.debug("bus.close_failed", port=instance.port, error=str(exc))
    if sock is not None:
        sock.close()


def has_descriptor(instance: serial.SerialBase) -> bool:
    """Whether ``instance`` can be driven on a file descriptor of its own."""
    try:
        instance.fileno()
    except (AttributeError, NotImplementedError, OSError, io.UnsupportedOperation):
        return False
    return True
