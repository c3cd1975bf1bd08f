"""What every TCP server of the daemon does to the sockets it accepts."""

from __future__ import annotations

import asyncio
import contextlib
import socket


def no_delay(transport: asyncio.BaseTransport) -> None:
    """Send each answer as it is written, without waiting for the client's last ACK.

    asyncio sets TCP_NODELAY only on sockets whose ``proto`` is IPPROTO_TCP, and those a
    listener made by :func:`socket.create_server` accepts have proto 0: without this a
    kept-open connection's every answer after the first waited ~40 ms for a delayed ACK.
    """
    sock = transport.get_extra_info("socket")
    if sock is not None and sock.family in (socket.AF_INET, socket.AF_INET6):
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
