"""The HTTP listener's edges over real sockets: answers on a kept-open connection go out at
once, heads beyond the limits are refused, wrong tokens are throttled and logged in sum.

How long a kept-open connection's answers take is a figure (``benchmarks/edge_clients.py``);
here the socket option that makes it short.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket

import httpx
import pytest
from structlog.testing import capture_logs

from fcmaster.adapters.auth_failures import FAILURES_PER_WINDOW
from fcmaster.adapters.http import HttpAdapter
from tests.integration.gateway_double import FakeGateway
from tests.integration.http_harness import OPERATOR, OPERATOR_TOKEN, VIEWER, serving

STOP = {"action": "stop"}


async def test_a_kept_open_connection_answers_each_request_without_waiting_for_an_ack() -> None:
    gateway = FakeGateway()
    async with (
        serving(gateway) as adapter,
        httpx.AsyncClient(base_url=adapter.url, headers=OPERATOR) as client,
    ):
        for n in range(20):
            if n % 2:
                response = await client.post("/api/v1/drives/pump-1/commands", json=STOP)
            else:
                response = await client.get("/api/v1/drives")
            assert response.status_code == 200, response.text
        [connection] = adapter.guard.open  # all twenty on one connection
        assert connection.answered == 20
        sock = connection.transport.get_extra_info("socket")
        assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) != 0


async def _raw(adapter: HttpAdapter, request: bytes) -> bytes:
    """What the server answers ``request`` on a fresh connection, until it closes."""
    host, port = adapter.url.removeprefix("http://").split(":")
    reader, writer = await asyncio.open_connection(host, int(port))
    try:
        writer.write(request)
        async with asyncio.timeout(10):
            return await reader.read(-1)
    finally:
        writer.close()


AUTH = f"Authorization: {VIEWER['Authorization']}\r\n".encode()


@pytest.mark.parametrize(
    ("request_bytes", "status"),
    [
        pytest.param(
            b"GET /api/v1/drives?" + b"a" * 70_000 + b" HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
            414,
            id="70-KB-request-line",
        ),
        pytest.param(
            b"GET /api/v1/drives HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Big: "
            + b"b" * 100_000
            + b"\r\n\r\n",
            431,
            id="100-KB-header",
        ),
        pytest.param(
            b"GET /api/v1/drives HTTP/1.1\r\nHost: 127.0.0.1\r\n"
            + b"".join(b"X-N%d: 1\r\n" % n for n in range(3000))
            + b"\r\n",
            431,
            id="3000-headers",
        ),
    ],
)
async def test_a_head_beyond_the_limits_is_refused(request_bytes: bytes, status: int) -> None:
    async with serving(FakeGateway()) as adapter:
        answer = await _raw(adapter, request_bytes)
        assert answer.startswith(b"HTTP/1.1 %d " % status), answer[:200]
        assert adapter.guard.too_large == 1
        good = b"GET /api/v1/drives HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n"
        assert (await _raw(adapter, good + AUTH + b"\r\n")).startswith(b"HTTP/1.1 200 ")


async def test_a_head_that_trickles_in_is_judged_whole() -> None:
    async with serving(FakeGateway()) as adapter:
        host, port = adapter.url.removeprefix("http://").split(":")
        reader, writer = await asyncio.open_connection(host, int(port))
        answer = asyncio.create_task(reader.readline())
        writer.write(b"GET /api/v1/drives HTTP/1.1\r\nHost: 127.0.0.1\r\n")
        with contextlib.suppress(ConnectionError):
            for n in range(150):  # header lines one by one, each chunk small
                if answer.done():
                    break
                writer.write(b"X-N%d: 1\r\n" % n)
                await writer.drain()
                await asyncio.sleep(0.001)
        async with asyncio.timeout(10):
            status_line = await answer
        writer.close()
        assert status_line.startswith(b"HTTP/1.1 431 "), status_line


async def test_wrong_tokens_are_throttled_per_address_and_logged_in_sum() -> None:
    gateway = FakeGateway()
    wrong = {"Authorization": "Bearer guess-guess-guess-guess"}
    other = httpx.AsyncHTTPTransport(local_address="127.0.0.2")
    with capture_logs() as logs:
        async with (
            serving(gateway) as adapter,
            httpx.AsyncClient(base_url=adapter.url, headers=wrong) as guesser,
            httpx.AsyncClient(base_url=adapter.url, transport=other) as elsewhere,
        ):
            statuses = [
                (await guesser.post("/api/v1/drives/pump-1/commands", json=STOP)).status_code
                for _ in range(3 * FAILURES_PER_WINDOW)
            ]
            assert statuses == [401] * FAILURES_PER_WINDOW + [429] * 2 * FAILURES_PER_WINDOW
            throttled = await guesser.post(
                "/api/v1/drives/pump-1/commands", json=STOP, headers=OPERATOR
            )
            assert throttled.status_code == 429  # not even looked at, right or wrong
            assert 1 <= int(throttled.headers["retry-after"]) <= 60
            assert "too many failed authentications" in throttled.json()["reason"]
            # Another address is judged on its own.
            assert (await elsewhere.get("/api/v1/drives", headers=wrong)).status_code == 401
            response = await elsewhere.post(
                "/api/v1/drives/pump-1/commands",
                json=STOP,
                headers={"Authorization": f"Bearer {OPERATOR_TOKEN}"},
            )
            assert response.status_code == 200, response.text
    assert [c.action.value for _, c in gateway.executed] == ["stop"]
    events = [e["event"] for e in logs if e["event"].startswith("http.")]
    assert events.count("http.command_refused") == 0  # wrong tokens are not one line each
    assert events.count("http.auth_failed") == 2  # the first of each address
    assert events.count("http.auth_throttled") == 1
