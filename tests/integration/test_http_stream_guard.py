"""WebSocket streams inside the connection guard, over real sockets: capped, counted against
the connections, dropped when they stop reading, and each event serialised once.

How much the line keeps with hundreds of streams open is a figure, measured by
``benchmarks/edge_clients.py``; here the structure that keeps it: streams beyond the guard
are refused, a stop still gets through, a client that reads nothing is dropped.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import socket
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import httpx
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus

from fcmaster.adapters.http import HttpAdapter
from fcmaster.adapters.http_guard import STREAMS_PER_CLIENT, ConnectionGuard
from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.clock import MonotonicClock
from fcmaster.state import CommandCompleted
from tests.integration.gateway_double import FakeGateway
from tests.integration.http_harness import OPERATOR, VIEWER, http_settings, ws_url
from tests.integration.waiting import wait_for

LIMIT_S = 60.0
Socket = tuple[asyncio.StreamReader, asyncio.StreamWriter]


@asynccontextmanager
async def guarded(gateway: FakeGateway, guard: ConnectionGuard) -> AsyncIterator[HttpAdapter]:
    adapter = HttpAdapter(http_settings(), gateway)
    adapter.guard = guard
    async with asyncio.timeout(LIMIT_S), adapter:
        yield adapter


@asynccontextmanager
async def silent_streams(adapter: HttpAdapter, count: int) -> AsyncIterator[list[int]]:
    """``count`` streams asked for on raw sockets that read only the answer's status line
    (and a receive buffer kept small, so their backlog fills fast); yields each status."""
    host, port = adapter.url.removeprefix("http://").split(":")
    opened: list[asyncio.StreamWriter] = []
    statuses = []
    try:
        for _ in range(count):
            sock = socket.socket()
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            sock.setblocking(False)
            await asyncio.get_running_loop().sock_connect(sock, (host, int(port)))
            reader, writer = await asyncio.open_connection(sock=sock, limit=256)
            opened.append(writer)
            key = base64.b64encode(os.urandom(16)).decode()
            writer.write(
                (
                    f"GET /api/v1/stream HTTP/1.1\r\nHost: {host}:{port}\r\n"
                    f"Authorization: {VIEWER['Authorization']}\r\nUpgrade: websocket\r\n"
                    f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                    "Sec-WebSocket-Version: 13\r\n\r\n"
                ).encode()
            )
            line = await asyncio.wait_for(reader.readline(), 10)
            statuses.append(int(line.split()[1]))
        yield statuses
    finally:
        for writer in opened:
            writer.close()
            with contextlib.suppress(ConnectionError):
                await writer.wait_closed()


async def _stop(adapter: HttpAdapter) -> httpx.Response:
    async with httpx.AsyncClient(base_url=adapter.url, headers=OPERATOR) as client:
        return await client.post("/api/v1/drives/pump-1/commands", json={"action": "stop"})


def _command_done(n: int) -> CommandCompleted:
    command = Command(action=Action.READ, actor=f"reader-{n}", parameter="16-13" + " " * 200)
    return CommandCompleted(
        bus="line1", drive="pump-1", command=command, result=CommandResult(outcome=Outcome.DONE)
    )


async def test_streams_beyond_the_guard_are_refused_and_a_stop_still_gets_through() -> None:
    gateway = FakeGateway()
    guard = ConnectionGuard(clock=MonotonicClock(), head_timeout_s=60)
    async with guarded(gateway, guard) as adapter:
        async with silent_streams(adapter, 300) as statuses:
            assert statuses.count(101) == STREAMS_PER_CLIENT
            assert statuses.count(503) == 300 - STREAMS_PER_CLIENT
            assert guard.stream_count == STREAMS_PER_CLIENT
            assert gateway.hub.subscriptions == STREAMS_PER_CLIENT
            response = await _stop(adapter)
            assert response.status_code == 200, response.text
            assert [c.action.value for _, c in gateway.executed] == ["stop"]
        await wait_for(lambda: guard.stream_count == 0, timeout_s=10)
        async with connect(ws_url(adapter), additional_headers=VIEWER) as ws:
            assert json.loads(await ws.recv())["type"] == "snapshot"  # the room is back


async def test_streams_count_against_the_connections_and_the_reserve_takes_stops() -> None:
    gateway = FakeGateway()
    guard = ConnectionGuard(
        clock=MonotonicClock(), max_connections=4, reserve=2, max_streams=4, head_timeout_s=60
    )
    async with guarded(gateway, guard) as adapter, silent_streams(adapter, 5) as statuses:
        assert statuses == [101, 101, 101, 101, 503]
        async with httpx.AsyncClient(base_url=adapter.url, headers=OPERATOR) as client:
            read = await client.get("/api/v1/drives/pump-1")
        assert read.status_code == 503  # four streams fill the four connections
        assert "only stop, coast and quick_stop" in read.json()["reason"]
        response = await _stop(adapter)
        assert response.status_code == 200, response.text
        assert response.json()["outcome"] == "done"


async def test_a_stream_that_reads_nothing_is_dropped_while_a_reader_keeps_its_events() -> None:
    gateway = FakeGateway()
    guard = ConnectionGuard(clock=MonotonicClock(), stream_stall_s=0.5)
    async with (
        guarded(gateway, guard) as adapter,
        silent_streams(adapter, 1) as statuses,
        connect(ws_url(adapter), additional_headers=VIEWER) as reader,
    ):
        assert statuses == [101]
        assert json.loads(await reader.recv())["type"] == "snapshot"
        n = 0

        async def read_all() -> None:
            while True:
                await reader.recv()

        reading = asyncio.create_task(read_all())
        async with asyncio.timeout(30):
            while guard.streams_dropped == 0:  # the bus's side: events keep coming
                for _ in range(20):
                    gateway.hub.publish(_command_done(n))
                    n += 1
                await asyncio.sleep(0.01)
        await wait_for(lambda: gateway.hub.subscriptions == 1, timeout_s=10)
        assert guard.stream_count == 1
        assert not reading.done()  # the reading client is still served
        reading.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await reading
        gateway.reply("pump-1", hz=33.0)
        async with asyncio.timeout(5):
            while (message := json.loads(await reader.recv()))["type"] != "drive":
                pass
        assert message["drive"]["output_frequency_hz"] == 33.0


async def test_each_event_is_serialised_once_for_every_stream() -> None:
    gateway = FakeGateway()
    async with (
        guarded(gateway, ConnectionGuard(clock=MonotonicClock())) as adapter,
        contextlib.AsyncExitStack() as stack,
    ):
        streams = [
            await stack.enter_async_context(connect(ws_url(adapter), additional_headers=VIEWER))
            for _ in range(5)
        ]
        for ws in streams:
            assert json.loads(await ws.recv())["type"] == "snapshot"
        before = adapter.streams.texts.serialised
        gateway.hub.publish(_command_done(1))
        for ws in streams:
            message = json.loads(await asyncio.wait_for(ws.recv(), 5))
            assert (message["type"], message["command"]["actor"]) == ("command", "reader-1")
        assert adapter.streams.texts.serialised - before == 1


async def test_a_refused_stream_is_told_why() -> None:
    guard = ConnectionGuard(clock=MonotonicClock(), max_streams=1)
    async with guarded(FakeGateway(), guard) as adapter:
        async with connect(ws_url(adapter), additional_headers=VIEWER):
            with pytest.raises(InvalidStatus) as caught:
                async with connect(ws_url(adapter), additional_headers=VIEWER):
                    pass
        assert caught.value.response.status_code == 503
        assert b"too many streams" in caught.value.response.body
