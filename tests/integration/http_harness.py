"""A Gateway of real parts (Hub, FleetState, LineStats) with an execute() the test controls,
and the HTTP adapter served on 127.0.0.1 with an ephemeral port.

Drive replies are folded into the fleet state exactly as a BusMaster reports them, through
``FleetState.drive_replied``; commands end with whatever ``respond`` returns.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import httpx

from fcmaster import config
from fcmaster.adapters.http import HttpAdapter
from fcmaster.adapters.settings import HttpSettings, Token
from fcmaster.service import Service
from tests.integration.gateway_double import FakeGateway

OPERATOR_TOKEN = "operator-secret-0123456789"
VIEWER_TOKEN = "viewer-secret-0123456789ab"
OPERATOR = {"Authorization": f"Bearer {OPERATOR_TOKEN}"}
VIEWER = {"Authorization": f"Bearer {VIEWER_TOKEN}"}


def http_settings(**overrides: Any) -> HttpSettings:
    """HTTP settings on an ephemeral loopback port with a viewer and an operator token."""
    fields: dict[str, Any] = {
        "listen": "127.0.0.1:0",
        "tokens": (
            Token(name="ops", role="operator", secret=OPERATOR_TOKEN),
            Token(name="scada", role="viewer", secret=VIEWER_TOKEN),
        ),
    }
    fields.update(overrides)
    return HttpSettings(**fields)


@asynccontextmanager
async def serving(
    gateway: FakeGateway, settings: HttpSettings | None = None, **options: Any
) -> AsyncIterator[HttpAdapter]:
    """The HTTP adapter over ``gateway``, listening until the block ends (bounded)."""
    async with asyncio.timeout(10):
        adapter = HttpAdapter(settings or http_settings(), gateway, **options)
        await adapter.__aenter__()
    try:
        yield adapter
    finally:
        async with asyncio.timeout(10):
            await adapter.__aexit__(None, None, None)


def ws_url(adapter: HttpAdapter, query: str = "") -> str:
    """The stream's ws:// URL."""
    return adapter.url.replace("http://", "ws://") + "/api/v1/stream" + query


SERVICE_CONFIG = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    drives:
      - {{name: pump-1, address: 1, control: bus, nominal_frequency_hz: 50, max_frequency_hz: 50}}
      - {{name: pump-2, address: 2, control: bus, nominal_frequency_hz: 50, max_frequency_hz: 60}}
      - {{name: fan-1, address: 3}}
  - name: line2
    port: sim://line2
    baudrate: 38400
    drives:
      - {{name: fan-2, address: 7}}
http:
  listen: 127.0.0.1:{port}
  tokens:
    - {{name: ops, role: operator, token: "{operator}"}}
    - {{name: scada, role: viewer, token: "{viewer}"}}
metrics: {{enabled: true}}
"""


def service_config(port: int) -> str:
    """Two simulated lines, four drives, and the HTTP adapter on ``port``."""
    return SERVICE_CONFIG.format(port=port, operator=OPERATOR_TOKEN, viewer=VIEWER_TOKEN)


async def wait_until_listening(url: str, timeout_s: float = 10.0) -> None:
    """Return once ``url`` answers HTTP (the service binds its adapter after the lines)."""
    async with asyncio.timeout(timeout_s), httpx.AsyncClient() as client:
        while True:
            try:
                await client.get(url + "/api/v1/openapi.json")
                return
            except httpx.TransportError:
                await asyncio.sleep(0.02)


class ServiceThread:
    """A real Service with simulated lines and the HTTP adapter, in a thread of its own.

    For callers that cannot share the test's event loop (schemathesis calls synchronously).
    """

    def __init__(self, text: str, port: int) -> None:
        self.url = f"http://127.0.0.1:{port}"
        self._text = text
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._failure: BaseException | None = None
        self._service: Service | None = None
        self._thread = threading.Thread(target=self._main, name="service", daemon=True)

    def _main(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._run())
        except BaseException as exc:  # reported to the test thread by start()
            self._failure = exc
            self._ready.set()
        finally:
            self._loop.close()

    async def _run(self) -> None:
        self._service = Service(config.parse(self._text))
        task = asyncio.create_task(self._service.run(install_signals=False))
        await wait_until_listening(self.url)
        self._ready.set()
        await task

    def start(self) -> None:
        self._thread.start()
        if not self._ready.wait(20) or self._failure is not None:
            raise RuntimeError(f"the service did not start: {self._failure!r}")

    def stop(self) -> None:
        if self._service is not None:
            self._loop.call_soon_threadsafe(self._service.stop)
        self._thread.join(20)
