"""The HTTP adapter: the API, its WebSocket stream, the dashboard and /metrics, in-process.

Theory of operation
-------------------
:class:`HttpAdapter` is an async context manager the service enters once the lines are up.
Entering binds the listening socket itself (so a taken port is a clear error, and port 0
works for tests), builds the FastAPI application of :mod:`fcmaster.adapters.api` and runs
uvicorn's server as a task in the daemon's own event loop: no thread, no second loop, and
the API reads the same fleet state the bus writes, without copying or locking. uvicorn's
signal capture is switched off — SIGTERM and SIGINT belong to the service, which leaves
this context on shutdown. Leaving ends every open stream (clients are told the server is
going away), lets requests in progress finish for a bounded time, and closes the socket.

Safety rules (DESIGN.md "Safety and trust"): the listener is 127.0.0.1:8080 unless
``http.listen`` says otherwise; with no tokens configured the API is read-only and must
listen on loopback (anything else is refused at start, naming ``http.listen``); CORS is off
unless ``http.cors_origins`` lists origins. With ``demo=True`` an operator token is made up
at start and printed, so the demo dashboard's buttons work.
"""

from __future__ import annotations

import asyncio
import contextlib
import secrets
import socket
from collections.abc import Iterator
from functools import partial
from types import TracebackType

import structlog
import uvicorn

from fcmaster.adapters.api import MAX_BODY_BYTES, create_app
from fcmaster.adapters.auth import (
    DEFAULT_PORT,
    Authenticator,
    Role,
    listen_problem,
    parse_listen,
)
from fcmaster.adapters.auth_failures import FailedAuthentications
from fcmaster.adapters.gateway import Gateway
from fcmaster.adapters.http_guard import HEAD_TIMEOUT_S, ConnectionGuard, guarded_protocol
from fcmaster.adapters.http_streams import guarded_stream
from fcmaster.adapters.settings import HttpSettings
from fcmaster.adapters.stream import StreamRegistry
from fcmaster.errors import ConfigError
from fcmaster.offloop import run_off_loop
from fcmaster.process_limits import connection_budget

log = structlog.get_logger("fcmaster.adapters.http")

__all__ = ["DEFAULT_PORT", "HttpAdapter", "parse_listen"]
SHUTDOWN_GRACE_S = 2  # requests in progress (a command awaiting its result) may finish
DEMO_TOKEN_NAME = "demo-operator"


class _Server(uvicorn.Server):
    """uvicorn's server without its signal handlers, telling when it accepts connections."""

    def __init__(self, config: uvicorn.Config) -> None:
        super().__init__(config)
        self.ready = asyncio.Event()

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        """The service owns SIGTERM and SIGINT; uvicorn must not take them over."""
        yield

    async def startup(self, sockets: list[socket.socket] | None = None) -> None:
        """Start serving, then say so."""
        await super().startup(sockets=sockets)
        self.ready.set()


class HttpAdapter:
    """Serves the HTTP API, stream, dashboard and metrics while the context is entered.

    Built by the service as ``HttpAdapter(settings, gateway, demo=…)``; pass
    ``metrics_enabled=False`` when the config's ``metrics.enabled`` is false.
    """

    def __init__(
        self,
        settings: HttpSettings,
        gateway: Gateway,
        *,
        demo: bool = False,
        metrics_enabled: bool = True,
    ) -> None:
        self.settings = settings
        self.gateway = gateway
        self.demo = demo
        self.metrics_enabled = metrics_enabled
        self.operator_token: str | None = None  # the demo's, once entered
        self._streams = StreamRegistry()
        self.guard = ConnectionGuard(clock=gateway.clock)
        self.failures = FailedAuthentications(gateway.clock.now)  # wrong tokens per address
        self._server: _Server | None = None
        self._task: asyncio.Task[None] | None = None
        self._socket: socket.socket | None = None
        self._address: tuple[str, int] | None = None

    @property
    def streams(self) -> StreamRegistry:
        """The open WebSocket streams."""
        return self._streams

    @property
    def url(self) -> str:
        """The base URL it listens on, e.g. ``http://127.0.0.1:8080`` (once entered)."""
        if self._address is None:
            raise RuntimeError("the HTTP adapter is not running")
        host, port = self._address
        return f"http://[{host}]:{port}" if ":" in host else f"http://{host}:{port}"

    def _authenticator(self, host: str) -> Authenticator:
        tokens = [(t.name, Role[t.role.upper()], t.secret) for t in self.settings.tokens]
        problem = listen_problem(self.settings.listen, has_tokens=bool(tokens))
        if problem:  # `check` refuses it too; --http-listen can still bring it here
            raise ConfigError([("http.listen", problem)])
        if self.demo:
            self.operator_token = secrets.token_urlsafe(24)
            tokens.append((DEMO_TOKEN_NAME, Role.OPERATOR, self.operator_token))
        return Authenticator(
            tokens,
            anonymous=self.settings.anonymous == "viewer" or not tokens,
            failures=self.failures,
        )

    def _bind(self, host: str, port: int) -> socket.socket:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        try:
            return socket.create_server((host, port), family=family, backlog=128)
        except OSError as exc:
            raise ConfigError(
                [("http.listen", f"cannot listen on {host}:{port}: {exc.strerror or exc}")]
            ) from exc

    async def __aenter__(self) -> HttpAdapter:
        if self._task is not None:
            raise RuntimeError("the HTTP adapter is already running")
        host, port = parse_listen(self.settings.listen)
        self.guard.fit(connection_budget())  # what the open-file limit leaves to connections
        auth = self._authenticator(host)
        # About 0.1 s of Python: off the loop, as a reload starts it while the lines run.
        app = await run_off_loop(
            partial(
                create_app,
                self.gateway,
                auth,
                metrics_enabled=self.metrics_enabled,
                cors_origins=tuple(self.settings.cors_origins),
                streams=self._streams,
            )
        )
        config = uvicorn.Config(
            app,
            log_config=None,  # structlog owns logging; uvicorn's own warnings still show
            log_level="warning",
            access_log=False,  # and so ?token= never lands in a log
            lifespan="off",
            ws=guarded_stream(self.guard),  # counted, and dropped when it stops reading
            ws_max_size=MAX_BODY_BYTES,
            proxy_headers=False,  # the peer address decides loopback, not X-Forwarded-For
            server_header=False,
            http=guarded_protocol(self.guard),  # timeouts, caps, a reserve for stops
            timeout_keep_alive=int(HEAD_TIMEOUT_S),
            timeout_graceful_shutdown=SHUTDOWN_GRACE_S,
        )
        self._socket = self._bind(host, port)
        bound = self._socket.getsockname()
        self._address = (str(bound[0]), int(bound[1]))
        self._server = _Server(config)
        self._task = asyncio.create_task(
            self._server.serve(sockets=[self._socket]), name="http.server"
        )
        server = self._server
        self._task.add_done_callback(lambda _: server.ready.set())  # failed as it started
        await server.ready.wait()
        if self._task.done():
            task, self._task, self._server = self._task, None, None
            self._socket.close()
            self._socket = self._address = None
            task.result()  # raises what stopped it
            raise RuntimeError("the HTTP server stopped as it started")
        self._task.add_done_callback(_report_end)
        log.info(
            "http.listening",
            url=self.url,
            tokens=len(self.settings.tokens),
            anonymous_reads=auth.anonymous,
            metrics=self.metrics_enabled,
            cors=bool(self.settings.cors_origins),
        )
        if self.demo and self.operator_token is not None:
            print(
                f"fcmaster demo: dashboard at {self.url}/#token={self.operator_token}\n"
                f"  operator token ({DEMO_TOKEN_NAME}): {self.operator_token}",
                flush=True,
            )
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        server, task, sock = self._server, self._task, self._socket
        if server is None or task is None:
            return
        log.info("http.closing")
        try:
            self._streams.close_all()
            server.should_exit = True
            done, _ = await asyncio.wait((task,), timeout=SHUTDOWN_GRACE_S + 3.0)
            if not done:
                server.force_exit = True
                task.cancel()
                await asyncio.wait((task,))
        finally:
            if sock is not None:
                sock.close()
            self._server = self._task = self._socket = None
            self._address = None
            log.info("http.stopped")


def _report_end(task: asyncio.Task[None]) -> None:
    if task.cancelled():
        return
    failure = task.exception()
    if failure is not None:
        log.error("http.failed", error=repr(failure))
