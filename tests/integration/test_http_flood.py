"""Connections held open to lock operators out, over real sockets: a stop still gets through.

The flood comes from many loopback addresses (127.0.0.2, .3, …) as it would from many hosts
on a plant network, so the per-client cap alone would not stop it. The guard's limits are
made small here so that a few dozen sockets reach them; the figures at the real limits
(300 idle and 100 half-open connections) come from ``benchmarks/http_flood.py``.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import httpx
import pytest

from fcmaster.adapters.http import HttpAdapter
from fcmaster.adapters.http_guard import ConnectionGuard
from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.clock import MonotonicClock
from tests.integration.gateway_double import FakeGateway
from tests.integration.http_harness import OPERATOR, VIEWER, http_settings

LIMIT_S = 30.0
Socket = tuple[asyncio.StreamReader, asyncio.StreamWriter]
OPENED: list[asyncio.StreamWriter] = []


@pytest.fixture(autouse=True)
async def _close_sockets() -> AsyncIterator[None]:
    yield
    for writer in OPENED:
        writer.close()
        with contextlib.suppress(ConnectionError):
            await writer.wait_closed()
    OPENED.clear()


@asynccontextmanager
async def guarded(gateway: FakeGateway, guard: ConnectionGuard) -> AsyncIterator[HttpAdapter]:
    adapter = HttpAdapter(http_settings(), gateway)
    adapter.guard = guard
    async with asyncio.timeout(LIMIT_S), adapter:
        yield adapter


async def _connect(adapter: HttpAdapter, n: int, first: bytes = b"") -> Socket:
    host, port = adapter.url.removeprefix("http://").split(":")
    reader, writer = await asyncio.open_connection(
        host, int(port), local_addr=(f"127.0.0.{2 + n % 200}", 0)
    )
    OPENED.append(writer)
    if first:
        writer.write(first)
        await writer.drain()
    return reader, writer


async def _closed_by_server(sock: Socket, within_s: float) -> bool:
    try:
        return await asyncio.wait_for(sock[0].read(), within_s) == b""
    except (TimeoutError, ConnectionError):
        return False


async def _stop(adapter: HttpAdapter) -> tuple[httpx.Response, float]:
    started = time.monotonic()
    async with httpx.AsyncClient(base_url=adapter.url, headers=OPERATOR) as client:
        response = await client.post("/api/v1/drives/pump-1/commands", json={"action": "stop"})
    return response, time.monotonic() - started


async def test_idle_and_half_open_connections_make_room_for_an_operator_stop() -> None:
    gateway = FakeGateway()
    guard = ConnectionGuard(
        clock=MonotonicClock(), max_connections=30, per_client=100, reserve=4, head_timeout_s=60
    )
    async with guarded(gateway, guard) as adapter:
        idle = [await _connect(adapter, n) for n in range(30)]
        half = [
            await _connect(adapter, n, b"POST /api/v1/drives/pump-1/commands HTTP/1.1\r\nHo")
            for n in range(30, 40)
        ]
        await asyncio.sleep(0.2)
        assert len(guard.open) == 30  # the ten half-open ones evicted the ten oldest idle
        assert all([await _closed_by_server(s, 5) for s in idle[:10]])
        # How fast is benchmarks/http_flood.py's figure; here it must get through at all
        # (the client's own 5 s timeout would fail the test).
        response, _ = await _stop(adapter)
        assert response.status_code == 200, response.text
        assert response.json()["outcome"] == "done"
        assert [c.action.value for _, c in gateway.executed] == ["stop"]
        for sock in half:  # the youngest were left alone: the oldest idle ones made room
            assert not await _closed_by_server(sock, 0.1)


async def test_a_connection_that_sends_nothing_or_half_a_request_is_closed_in_time() -> None:
    guard = ConnectionGuard(clock=MonotonicClock(), head_timeout_s=0.5, body_timeout_s=0.5)
    async with guarded(FakeGateway(), guard) as adapter:
        silent = await _connect(adapter, 1)
        half_head = await _connect(adapter, 2, b"GET /api/v1/drives HTTP/1.1\r\nHost: x")
        half_body = await _connect(
            adapter,
            3,
            b"POST /api/v1/drives/pump-1/commands HTTP/1.1\r\nHost: 127.0.0.1\r\n"
            b"Content-Type: application/json\r\nContent-Length: 100\r\n\r\n{",
        )
        started = time.monotonic()
        for sock in (silent, half_head, half_body):
            assert await _closed_by_server(sock, 10)
        assert time.monotonic() - started < 10
        assert guard.timed_out == 3
        assert guard.open == {}


async def test_one_client_cannot_hold_more_than_its_share() -> None:
    guard = ConnectionGuard(clock=MonotonicClock(), per_client=5, head_timeout_s=60)
    async with guarded(FakeGateway(), guard) as adapter:
        first = [await _connect(adapter, 0) for _ in range(5)]
        sixth = await _connect(adapter, 0)
        assert await _closed_by_server(first[0], 5)  # its own oldest idle one made room
        assert guard.per_host == {"127.0.0.2": 5}
        sixth[1].write(b"GET /api/v1/whoami HTTP/1.1\r\nHost: 127.0.0.1\r\n")
        sixth[1].write(f"Authorization: {VIEWER['Authorization']}\r\n\r\n".encode())
        assert (await sixth[0].readline()).startswith(b"HTTP/1.1 200")


async def test_when_every_connection_is_busy_the_reserve_takes_stops_only() -> None:
    release = asyncio.Event()

    async def slow(_drive: str, command: Command) -> CommandResult:
        if command.action.value == "read":
            await release.wait()
        return CommandResult(outcome=Outcome.DONE)

    gateway = FakeGateway(respond=slow)
    guard = ConnectionGuard(clock=MonotonicClock(), max_connections=6, reserve=2, head_timeout_s=60)
    async with guarded(gateway, guard) as adapter:
        busy = []
        for n in range(6):  # six operator reads that wait for the line: nothing idle
            sock = await _connect(adapter, n)
            sock[1].write(
                b"GET /api/v1/drives/pump-1/parameters/16-13 HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                + f"Authorization: {OPERATOR['Authorization']}\r\n\r\n".encode()
            )
            busy.append(sock)
        await asyncio.sleep(0.3)
        assert not guard.idle
        async with httpx.AsyncClient(base_url=adapter.url, headers=OPERATOR) as client:
            read = await client.get("/api/v1/drives/pump-1")
        assert read.status_code == 503
        assert "only stop, coast and quick_stop" in read.json()["reason"]
        response, _ = await _stop(adapter)
        assert response.status_code == 200, response.text
        assert response.json()["outcome"] == "done"
        release.set()
        for reader, _ in busy:
            assert (await reader.readline()).startswith(b"HTTP/1.1 200")
