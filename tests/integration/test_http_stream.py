"""The WebSocket stream over real sockets: snapshot, events, auth, origins, slow clients."""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any

import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import InvalidStatus

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.state import CommandCompleted, LineChanged
from tests.integration.gateway_double import FakeGateway
from tests.integration.http_harness import (
    OPERATOR,
    OPERATOR_TOKEN,
    VIEWER,
    serving,
    ws_url,
)


async def _next(ws: ClientConnection, kind: str) -> dict[str, Any]:
    """The next message of type ``kind`` (others are skipped)."""
    async with asyncio.timeout(5):
        while True:
            message: dict[str, Any] = json.loads(await ws.recv())
            if message["type"] == kind:
                return message


async def test_a_client_gets_a_snapshot_then_every_change() -> None:
    gateway = FakeGateway()
    async with (
        serving(gateway) as adapter,
        connect(ws_url(adapter), additional_headers=VIEWER) as ws,
    ):
        snapshot = await _next(ws, "snapshot")
        assert [d["name"] for d in snapshot["drives"]] == ["pump-1", "fan-1"]
        assert snapshot["buses"][0]["name"] == "line1"
        # each drive's configured frequencies, so a page can say a reference's Hz
        assert snapshot["limits"]["pump-1"] == {
            "nominal_frequency_hz": 50.0,
            "min_frequency_hz": 0.0,
            "max_frequency_hz": 50.0,
        }
        assert set(snapshot["limits"]) == {"pump-1", "fan-1"}

        gateway.reply("pump-1", running=True, hz=12.5)
        assert (await _next(ws, "availability")) == {
            "type": "availability",
            "bus": "line1",
            "drive": "pump-1",
            "online": True,
        }
        update = await _next(ws, "drive")
        assert (update["drive"]["name"], update["drive"]["output_frequency_hz"]) == ("pump-1", 12.5)

        gateway.reply("pump-1", alarms=((14, "Earth fault"),))
        condition = await _next(ws, "condition")
        assert (condition["kind"], condition["code"], condition["text"], condition["active"]) == (
            "alarm",
            14,
            "Earth fault",
            True,
        )

        command = Command(action=Action.STOP, actor="ops")
        gateway.hub.publish(
            CommandCompleted(
                bus="line1",
                drive="pump-1",
                command=command,
                result=CommandResult(outcome=Outcome.DONE),
            )
        )
        completed = await _next(ws, "command")
        assert completed["command"] == {"action": "stop", "actor": "ops"}
        assert completed["result"]["outcome"] == "done"

        gateway.hub.publish(LineChanged(bus="line1", up=True, stats=gateway.lines()[0].stats))
        line = await _next(ws, "line")
        assert line["stats"]["latency_s"]["buckets"][-1]["le"] == "+Inf"


async def test_a_stream_can_be_narrowed_to_one_drive() -> None:
    gateway = FakeGateway()
    async with serving(gateway) as adapter:
        url = ws_url(adapter, "?drive=fan-1")
        async with connect(url, additional_headers=VIEWER) as ws:
            snapshot = await _next(ws, "snapshot")
            assert [d["name"] for d in snapshot["drives"]] == ["fan-1"]
            assert list(snapshot["limits"]) == ["fan-1"]
            gateway.reply("pump-1", hz=1.0)
            gateway.reply("fan-1", hz=2.0)
            update = await _next(ws, "drive")
            assert update["drive"]["name"] == "fan-1"


async def test_browsers_pass_the_token_in_the_query() -> None:
    async with (
        serving(FakeGateway()) as adapter,
        connect(ws_url(adapter, f"?token={OPERATOR_TOKEN}")) as ws,
    ):
        assert (await _next(ws, "snapshot"))["drives"]


@pytest.mark.parametrize(
    ("query", "headers"),
    [
        pytest.param("", {}, id="no-token"),
        pytest.param("?token=wrong-token-wrong-token", {}, id="wrong-token"),
        pytest.param("", {**OPERATOR, "Origin": "http://evil.example"}, id="foreign-origin"),
    ],
)
async def test_a_stream_is_refused_without_a_token_or_from_a_foreign_page(
    query: str, headers: dict[str, str]
) -> None:
    async with serving(FakeGateway()) as adapter:
        with pytest.raises(InvalidStatus) as caught:
            async with connect(ws_url(adapter, query), additional_headers=headers):
                pass
        assert caught.value.response.status_code == 403


async def test_the_page_s_own_origin_is_accepted() -> None:
    async with serving(FakeGateway()) as adapter:
        origin = {"Origin": adapter.url, **VIEWER}
        async with connect(ws_url(adapter), additional_headers=origin) as ws:
            assert (await _next(ws, "snapshot"))["type"] == "snapshot"


async def test_a_client_that_never_reads_does_not_slow_publishing() -> None:
    gateway = FakeGateway()
    async with serving(gateway) as adapter:
        async with connect(
            ws_url(adapter), additional_headers=VIEWER, max_queue=1, close_timeout=0.5
        ) as stalled:
            await _next(stalled, "snapshot")
            started = time.perf_counter()
            for n in range(5000):  # the bus's side: fold replies in and publish
                gateway.reply("pump-1", running=True, hz=float(n % 50))
                if n % 100 == 0:
                    await asyncio.sleep(0)  # let the stalled client's writer run into its wall
            publishing_s = time.perf_counter() - started
            async with connect(ws_url(adapter), additional_headers=VIEWER) as fresh:
                snapshot = await _next(fresh, "snapshot")
                assert snapshot["drives"][0]["output_frequency_hz"] == 49.0
        assert publishing_s < 2.0  # about 30 µs a reply; the stalled client costs nothing
        assert gateway.hub.subscriptions == 0  # both subscriptions were closed


async def test_stopping_the_adapter_ends_open_streams_with_going_away() -> None:
    gateway = FakeGateway()
    async with serving(gateway) as adapter:
        ws = await connect(ws_url(adapter), additional_headers=VIEWER)
        await _next(ws, "snapshot")
    async with asyncio.timeout(5):
        await ws.wait_closed()
    assert ws.close_code == 1001  # going away
    assert gateway.hub.subscriptions == 0
