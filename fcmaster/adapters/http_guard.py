"""Connections that cannot lock operators out: timeouts, a cap per client, and a reserve.

Why not uvicorn's own settings: ``limit_concurrency`` answers 503 to *every* new request
once that many connections are open, and uvicorn (h11) closes neither a connection that
never sends a byte nor one that sends half a request — its keep-alive timeout starts only
after a first response. So 260 half-open connections lock every operator out, stops
included, for as long as they stay open. The HTTP protocol here is uvicorn's h11 protocol
with a :class:`ConnectionGuard` around it:

- **timeouts**: a connection must deliver a whole request head within
  :data:`HEAD_TIMEOUT_S` of opening or of its last answer (an idle keep-alive connection
  is closed then too), and a request's body within :data:`BODY_TIMEOUT_S` of its head;
  otherwise it is closed.
- **idle ones make room**: a connection waiting for a request head is *idle*. When a new
  connection would pass :data:`PER_CLIENT` connections for its address, the oldest idle one
  of that address is closed to make room; when it would pass :data:`MAX_CONNECTIONS` in
  all, the oldest idle one of the address holding the most connections. A client that
  holds connections without asking anything so loses them to whoever connects next, and
  an operator's new connection gets in while any connection is idle. An address that lost
  a connection so (or to a timeout) cannot take an idle one's place again for
  :data:`HEAD_TIMEOUT_S` while the server is full: a flood that reconnects at once does
  not churn an operator's new connection out before its request is read.

- **a reserve**: when every connection carries a request in progress (none is idle), up to
  :data:`RESERVE` more are taken, and requests on those are served only if they are a
  stop, coast or quick_stop (:data:`RESERVE_KEY` in the request's ``state``; the API
  answers anything else 503). Beyond that, a new connection is closed at once.

- **streams count too**: a WebSocket stream is a connection that is never idle. At most
  :data:`MAX_STREAMS` are open (:data:`STREAMS_PER_CLIENT` from one address), inside
  :data:`MAX_CONNECTIONS`, so streams can never take the room requests and the reserve need;
  an upgrade beyond that is answered 503. A stream whose client stops reading is dropped:
  its socket's send buffer is small (:mod:`.http_streams`), the protocol stops
  writing once the transport's buffer is full, and a transport that stays full for
  :data:`STREAM_STALL_S` is aborted, so a silent client costs neither memory nor time.

- **heads of a sane size**: a request line longer than :data:`MAX_REQUEST_LINE` is answered
  414, a head longer than :data:`MAX_HEAD_BYTES` or with more than :data:`MAX_HEADERS`
  header lines 431, and the connection is closed. h11 alone limits only a head that is
  still incomplete, so one that arrives whole in a chunk of any size would be taken.

Counting happens in the protocol callbacks, on the event loop: no locks, no per-request
cost beyond a dict lookup.
"""

from __future__ import annotations

import asyncio
import json
from collections import OrderedDict
from typing import Any, Final

import h11
import structlog
from uvicorn.protocols.http.h11_impl import H11Protocol

from fcmaster.adapters.tcp import no_delay
from fcmaster.clock import Clock

log = structlog.get_logger("fcmaster.adapters.http")

HEAD_TIMEOUT_S: Final = 5.0  # a whole request head, from connecting or the last answer
BODY_TIMEOUT_S: Final = 10.0  # a request's body, from its head
MAX_CONNECTIONS: Final = 256  # HTTP connections in all, WebSocket streams among them
PER_CLIENT: Final = 64  # connections from one address
SHUTDOWN_HEAD_S: Final = 0.5  # stopping: a request already on its way is still read
RESERVE: Final = 16  # beyond MAX_CONNECTIONS, for stops only, when none is idle
MAX_PENALTIES: Final = 4096  # addresses remembered for holding connections idle
RESERVE_KEY: Final = "fcmaster.reserve"  # in a request's scope["state"]: stops only
MAX_REQUEST_LINE: Final = 8 * 1024  # bytes of "GET /path?query HTTP/1.1"
MAX_HEAD_BYTES: Final = 32 * 1024  # the request line and every header
MAX_HEADERS: Final = 100  # header lines
MAX_STREAMS: Final = 128  # WebSocket streams in all (each one of MAX_CONNECTIONS)
STREAMS_PER_CLIENT: Final = 32  # streams from one address
STREAM_STALL_S: Final = 10.0  # a stream whose client reads nothing this long is dropped


class ConnectionGuard:
    """The connections of one server: which are idle, and who to close to make room."""

    def __init__(
        self,
        *,
        clock: Clock,
        max_connections: int = MAX_CONNECTIONS,
        per_client: int = PER_CLIENT,
        reserve: int = RESERVE,
        head_timeout_s: float = HEAD_TIMEOUT_S,
        body_timeout_s: float = BODY_TIMEOUT_S,
        max_streams: int = MAX_STREAMS,
        streams_per_client: int = STREAMS_PER_CLIENT,
        stream_stall_s: float = STREAM_STALL_S,
    ) -> None:
        self.clock = clock  # times the penalties below (the timeouts are the loop's timers)
        self.max_connections = max_connections
        self.per_client = per_client
        self.reserve = reserve
        self.head_timeout_s = head_timeout_s
        self.body_timeout_s = body_timeout_s
        self.open: dict[GuardedProtocol, str] = {}  # connection → client address
        self.idle: OrderedDict[GuardedProtocol, None] = OrderedDict()  # oldest first
        self.per_host: dict[str, int] = {}
        self.evicted = self.refused = self.timed_out = self.too_large = 0
        self.max_streams = max_streams
        self.streams_per_client = streams_per_client
        self.stream_stall_s = stream_stall_s
        self.streams: dict[str, int] = {}  # client address → open streams
        self.stream_count = self.streams_refused = self.streams_dropped = 0
        # Addresses that lost a connection for holding it idle, until when: while the
        # server is full they cannot take an idle connection's place again, so that a
        # flood that reconnects at once does not churn an operator's new connection out.
        self.penalties: OrderedDict[str, float] = OrderedDict()

    def fit(self, budget: int) -> None:
        """Hold at most ``budget`` connections in all, reserve included (the file limit's).

        Past the open-file limit nothing can be accepted, not even a stop: the guard must
        be full, and evicting, before the process runs out of descriptors.
        """
        if self.max_connections + self.reserve <= budget:
            return
        was = self.max_connections
        self.max_connections = max(1, budget - self.reserve)
        self.max_streams = min(self.max_streams, max(1, self.max_connections // 2))
        self.per_client = min(self.per_client, self.max_connections)
        log.warning(
            "http.connections_fitted", max_connections=self.max_connections, was=was,
            max_streams=self.max_streams, reason="the open-file limit is low",
        )  # fmt: skip

    def penalise(self, host: str) -> None:
        """``host`` held a connection without using it (evicted, or timed out)."""
        self.penalties[host] = self.clock.now() + self.head_timeout_s
        self.penalties.move_to_end(host)
        if len(self.penalties) > MAX_PENALTIES:
            self.penalties.popitem(last=False)

    def _penalised(self, host: str) -> bool:
        until = self.penalties.get(host)
        if until is None:
            return False
        if until > self.clock.now():
            return True
        del self.penalties[host]
        return False

    def admit(self, conn: GuardedProtocol, host: str) -> bool:
        """Take a new connection, closing idle ones to make room; False: close it."""
        if self.per_host.get(host, 0) >= self.per_client and not self._evict(host):
            self.refused += 1
            return False
        reserved = False
        if self._count() >= self.max_connections:
            if self.idle:  # make room, unless this address just lost an idle one itself
                if self._penalised(host) or not self._evict(None):
                    self.refused += 1
                    return False
                # in the place of a reserve connection, it is one too
                reserved = self._count() >= self.max_connections
            elif self._count() < self.max_connections + self.reserve:
                reserved = True  # every connection is busy: this one takes stops only
            else:
                self.refused += 1
                return False
        self.open[conn] = host
        self.per_host[host] = self.per_host.get(host, 0) + 1
        self.idle[conn] = None
        conn.reserved = reserved
        return True

    def _count(self) -> int:
        return len(self.open) + self.stream_count

    def admit_stream(self, host: str) -> bool:
        """A connection of ``host`` asks to become a stream; False: answer it 503."""
        if (
            self.stream_count >= self.max_streams
            or self.streams.get(host, 0) >= self.streams_per_client
        ):
            self.streams_refused += 1
            return False
        self.stream_count += 1
        self.streams[host] = self.streams.get(host, 0) + 1
        return True

    def stream_gone(self, host: str) -> None:
        """A stream of ``host`` closed."""
        self.stream_count -= 1
        self.streams[host] -= 1
        if not self.streams[host]:
            del self.streams[host]

    def busy(self, conn: GuardedProtocol) -> None:
        """``conn`` carries a request now."""
        self.idle.pop(conn, None)

    def waiting(self, conn: GuardedProtocol) -> None:
        """``conn`` waits for its next request head."""
        if conn in self.open:
            self.idle[conn] = None
            self.idle.move_to_end(conn)

    def gone(self, conn: GuardedProtocol) -> None:
        """``conn`` closed (or became a WebSocket)."""
        host = self.open.pop(conn, None)
        self.idle.pop(conn, None)
        if host is not None:
            self.per_host[host] -= 1
            if not self.per_host[host]:
                del self.per_host[host]

    def _evict(self, host: str | None) -> bool:
        """Close the oldest idle connection of ``host`` (None: of whoever holds the most)."""
        if host is None and self.idle:
            # The address holding the most connections gives one up first: a flood from a
            # few hosts never makes an operator's one new connection the victim.
            most = max(self.per_host[self.open[c]] for c in self.idle)
            victim = next((c for c in self.idle if self.per_host[self.open[c]] == most), None)
        else:
            victim = next((c for c in self.idle if self.open[c] == host), None)
        if victim is None:
            return False
        self.evicted += 1
        self.penalise(self.open[victim])
        self.gone(victim)
        victim.close_now()
        return True


class GuardedProtocol(H11Protocol):
    """uvicorn's h11 protocol, admitted and timed by a :class:`ConnectionGuard`."""

    guard: ConnectionGuard  # set on the subclass :func:`guarded_protocol` makes

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.reserved = False
        self.answered = 0  # requests answered on this connection
        self.closing = False  # the server is stopping
        self._deadline: asyncio.TimerHandle | None = None
        self._head: bytearray | None = bytearray()  # the head coming in (None: not looking)
        self._line_end = -1  # where its request line ends (-1: not seen yet)
        self._lines = 0  # line ends seen in it

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        """Admit the connection or close it at once; start waiting for a request head."""
        no_delay(transport)
        super().connection_made(transport)
        host = self.client[0] if self.client else "?"
        if not self.guard.admit(self, host):
            self.close_now()
            return
        self._expect_head()

    def connection_lost(self, exc: Exception | None) -> None:
        """Forget the connection."""
        self._cancel_deadline()
        self.guard.gone(self)
        super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        """Refuse a head beyond the limits before h11 takes it in."""
        # Only a new request's head: not the rest of a body the client still sends after
        # its answer (a 413's), which h11 reads on and throws away.
        looking = self._head is not None and self.conn.their_state is h11.IDLE
        if looking and not self._head_fits(data):
            return
        super().data_received(data)

    def _head_fits(self, data: bytes) -> bool:
        # Each chunk is looked at once (a head sent a byte at a time costs no more than one
        # sent whole): the scans start where the last one stopped.
        head = self._head
        assert head is not None
        seen = len(head)
        head += data
        end = head.find(b"\r\n\r\n", max(0, seen - 3))
        size = end if end >= 0 else len(head)
        if self._line_end < 0:
            self._line_end = head.find(b"\r\n", max(0, seen - 1), size)
        self._lines += head.count(b"\r\n", max(0, seen - 1), size)
        too_large = "Request Header Fields Too Large"
        if (self._line_end if self._line_end >= 0 else size) > MAX_REQUEST_LINE:
            return self._refuse(414, "URI Too Long", f"request line over {MAX_REQUEST_LINE} bytes")
        if size > MAX_HEAD_BYTES:
            return self._refuse(431, too_large, f"head over {MAX_HEAD_BYTES} bytes")
        if self._lines > MAX_HEADERS:
            return self._refuse(431, too_large, f"over {MAX_HEADERS} headers")
        if end >= 0:  # whole and within the limits: the rest is h11's
            self._head = None
        return True

    def _expect_next_head(self) -> None:
        self._head = bytearray()
        self._line_end = -1
        self._lines = 0

    def _refuse(self, status: int, phrase: str, reason: str) -> bool:
        self.guard.too_large += 1
        body = json.dumps({"reason": reason}).encode()
        self.transport.write(
            f"HTTP/1.1 {status} {phrase}\r\ncontent-type: application/json\r\n"
            f"content-length: {len(body)}\r\nconnection: close\r\n\r\n".encode()
            + body
        )
        self._head = None
        self.close_now()
        return False

    def handle_events(self) -> None:
        """Let uvicorn read events; a request head now received makes the connection busy."""
        had = self.cycle
        super().handle_events()
        cycle = self.cycle
        if cycle is not None and cycle is not had and not cycle.response_complete:
            self.guard.busy(self)
            if self.closing:
                cycle.keep_alive = False
            if self.reserved:
                cycle.scope.setdefault("state", {})[RESERVE_KEY] = True
            self._cancel_deadline()
            if self.conn.their_state is h11.SEND_BODY:
                self._deadline = self.loop.call_later(self.guard.body_timeout_s, self._body_late)

    def on_response_complete(self) -> None:
        """Answered: wait for the next request head (or close when none comes in time)."""
        super().on_response_complete()
        self.answered += 1
        if not self.transport.is_closing() and (self.cycle is None or self.cycle.response_complete):
            self.guard.waiting(self)
            self._expect_next_head()  # the next request's head is looked at too
            if self.closing:
                self._shut()
            else:
                self._expect_head()

    def shutdown(self) -> None:
        """The server stops: a request already on its way is still read and answered.

        uvicorn would close a connection without a request in progress at once, and a
        client whose request was in flight then gets no answer at all; here it gets
        :data:`SHUTDOWN_HEAD_S` to arrive (and is answered, "shutting down"), then closes.
        """
        self.closing = True
        if self.cycle is None or self.cycle.response_complete:
            self._cancel_deadline()
            self._deadline = self.loop.call_later(SHUTDOWN_HEAD_S, self._shut)
        else:
            super().shutdown()

    def _shut(self) -> None:
        self._deadline = None
        if not self.transport.is_closing():
            super().shutdown()

    def handle_websocket_upgrade(self, event: h11.Request) -> None:
        """The connection becomes a stream, counted as one (or is answered 503)."""
        self._cancel_deadline()
        self.guard.gone(self)
        if not self.guard.admit_stream(self.client[0] if self.client else "?"):
            body = b"too many streams are open; try again later"
            headers = [(b"content-type", b"text/plain; charset=utf-8"), (b"connection", b"close")]
            headers.append((b"content-length", str(len(body)).encode()))
            for part in (h11.Response(status_code=503, headers=headers), h11.Data(data=body)):
                self.transport.write(self.conn.send(part) or b"")
            self.transport.write(self.conn.send(h11.EndOfMessage()) or b"")
            self.transport.close()
            return
        super().handle_websocket_upgrade(event)

    def close_now(self) -> None:
        """Close without an answer (there is no request to answer)."""
        self._cancel_deadline()
        if not self.transport.is_closing():
            self.transport.close()

    def _expect_head(self) -> None:
        self._cancel_deadline()
        self._deadline = self.loop.call_later(self.guard.head_timeout_s, self._head_late)

    def _head_late(self) -> None:
        self._deadline = None
        if self.cycle is None or self.cycle.response_complete:
            self.guard.timed_out += 1
            if not self.answered:  # held without asking anything (not a keep-alive ending)
                self.guard.penalise(self.client[0] if self.client else "?")
            self.close_now()

    def _body_late(self) -> None:
        self._deadline = None
        if self.conn.their_state is h11.SEND_BODY:  # the app still waits for the body
            self.guard.timed_out += 1
            self.close_now()

    def _cancel_deadline(self) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None


def guarded_protocol(guard: ConnectionGuard) -> type[GuardedProtocol]:
    """The protocol class for one server, bound to its guard (uvicorn's ``http=``)."""
    return type("GuardedH11Protocol", (GuardedProtocol,), {"guard": guard})
