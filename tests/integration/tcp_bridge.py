"""A serial device server in threads: one local port served on TCP, raw or as RFC 2217.

Serial device servers put an RS-485 line on the network either as a raw TCP stream
(``socket://``) or speaking RFC 2217, where the client also sets the baud rate and format
remotely (``rfc2217://``). The bridge serves one local port (the simulator's pty) both
ways; pyserial's :class:`serial.rfc2217.PortManager` does the RFC 2217 side, as in a real
device server.
"""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Iterator

import serial
import serial.rfc2217


class _PtyPort(serial.Serial):  # type: ignore[misc]
    """A pty has no modem lines (their ioctl fails): reported low, and setting them is a no-op."""

    def _update_dtr_state(self) -> None:
        pass

    def _update_rts_state(self) -> None:
        pass

    def _update_break_state(self) -> None:
        pass

    @property
    def cts(self) -> bool:
        return False

    @property
    def dsr(self) -> bool:
        return False

    @property
    def ri(self) -> bool:
        return False

    @property
    def cd(self) -> bool:
        return False


class _Connection:
    """What PortManager writes its answers to: the client's socket."""

    def __init__(self, sock: socket.socket) -> None:
        self._sock = sock
        self._lock = threading.Lock()

    def write(self, data: bytes) -> None:
        with self._lock:
            self._sock.sendall(data)


class TcpBridge:
    """Serves ``device`` to one TCP client at a time, on 127.0.0.1 at :attr:`port`."""

    def __init__(self, device: str, *, rfc2217: bool, baudrate: int = 19200) -> None:
        self.device = device
        self.rfc2217 = rfc2217
        # A raw TCP server's serial side is set up on the server itself (its web page) to
        # the line's rate; an RFC 2217 client sets it remotely, so it starts elsewhere.
        self.baudrate = baudrate
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.settimeout(0.1)
        self.port: int = self._listener.getsockname()[1]
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.clients = 0
        self.settings_seen: list[tuple[int, str]] = []  # (baud rate, parity) set remotely
        self._client: socket.socket | None = None

    @property
    def url(self) -> str:
        scheme = "rfc2217" if self.rfc2217 else "socket"
        return f"{scheme}://127.0.0.1:{self.port}"

    def start(self) -> None:
        self._spawn(self._accept)

    def stop(self) -> None:
        self._stop.set()
        self.drop_client()
        for thread in self._threads:
            thread.join(timeout=5)
        self._listener.close()

    def drop_client(self) -> None:
        """Cut the connection, as a device server that restarts does."""
        client, self._client = self._client, None
        if client is not None:
            with contextlib.suppress(OSError):
                client.shutdown(socket.SHUT_RDWR)
            client.close()

    def _spawn(self, target: object, *args: object) -> None:
        thread = threading.Thread(target=target, args=args, daemon=True)  # type: ignore[arg-type]
        self._threads.append(thread)
        thread.start()

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                client, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            self.clients += 1
            self._client = client
            self._serve(client)

    def _serve(self, client: socket.socket) -> None:
        port = _PtyPort(self.device, baudrate=self.baudrate, timeout=0.02)
        manager = serial.rfc2217.PortManager(port, _Connection(client)) if self.rfc2217 else None
        done = threading.Event()
        self._spawn(self._to_client, port, client, manager, done)
        client.settimeout(0.1)
        try:
            while not self._stop.is_set():
                try:
                    data = client.recv(4096)
                except TimeoutError:
                    continue
                except OSError:
                    break
                if not data:
                    break
                if manager is not None:
                    data = b"".join(manager.filter(data))
                    setting = (port.baudrate, port.parity)
                    if not self.settings_seen or self.settings_seen[-1] != setting:
                        self.settings_seen.append(setting)
                if data:
                    port.write(data)
        finally:
            done.set()
            with contextlib.suppress(OSError):
                client.close()
            port.close()

    def _to_client(
        self,
        port: serial.Serial,
        client: socket.socket,
        manager: serial.rfc2217.PortManager | None,
        done: threading.Event,
    ) -> None:
        while not done.is_set():
            try:
                data = port.read(4096)
            except (serial.SerialException, OSError, TypeError):
                return
            if not data:
                continue
            if manager is not None:
                data = b"".join(manager.escape(data))
            try:
                client.sendall(data)
            except OSError:
                return


@contextlib.contextmanager
def tcp_bridge(device: str, *, rfc2217: bool, baudrate: int = 19200) -> Iterator[TcpBridge]:
    """A running :class:`TcpBridge` for ``device``, stopped on exit."""
    bridge = TcpBridge(device, rfc2217=rfc2217, baudrate=baudrate)
    bridge.start()
    try:
        yield bridge
    finally:
        bridge.stop()
