"""WebSocket streams under the connection guard: counted, and dropped when they stop reading.

A stream's connection is admitted as a stream by :class:`~.http_guard.GuardedProtocol` when
it asks for the upgrade; from then on it is this protocol's. Its socket's kernel send buffer
is made small (:data:`STREAM_SEND_BUFFER`), so a client that reads nothing fills it soon;
uvicorn's protocol then stops writing (the transport's own buffer full: its sends wait, and
the stream's subscription conflates meanwhile); if that lasts the guard's
``stream_stall_s``, the connection is aborted: a close frame would wait behind what the
client never read.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
from typing import Any, Final

from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

from fcmaster.adapters.http_guard import ConnectionGuard, log

STREAM_SEND_BUFFER: Final = 32 * 1024  # the kernel's send buffer of a stream's socket


class GuardedStream(WebSocketsSansIOProtocol):
    """uvicorn's WebSocket protocol, counted by a :class:`ConnectionGuard`.

    A stream whose client reads nothing for the guard's ``stream_stall_s`` is dropped.
    """

    guard: ConnectionGuard  # set on the subclass :func:`guarded_stream` makes

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._stall: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        """Keep the kernel's share of a silent client's backlog small."""
        super().connection_made(transport)
        sock = transport.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, STREAM_SEND_BUFFER)

    def connection_lost(self, exc: Exception | None) -> None:
        """Forget the stream."""
        self._calm()
        self.guard.stream_gone(self.client[0] if self.client else "?")
        super().connection_lost(exc)

    def pause_writing(self) -> None:
        """The client is not taking what it was sent: it has a while to start again."""
        super().pause_writing()
        if self._stall is None:
            self._stall = self.loop.call_later(self.guard.stream_stall_s, self._stalled)

    def resume_writing(self) -> None:
        """The client reads again."""
        super().resume_writing()
        self._calm()

    def _calm(self) -> None:
        if self._stall is not None:
            self._stall.cancel()
            self._stall = None

    def _stalled(self) -> None:
        self._stall = None
        self.guard.streams_dropped += 1
        log.warning(
            "http.stream_dropped",
            client=self.client[0] if self.client else "?",
            reason=f"read nothing for {self.guard.stream_stall_s:g} s",
        )
        self.transport.abort()  # a close frame would wait behind what it never read


def guarded_stream(guard: ConnectionGuard) -> type[GuardedStream]:
    """The WebSocket protocol class for one server, bound to its guard (uvicorn's ``ws=``)."""
    return type("GuardedStream", (GuardedStream,), {"guard": guard})
