"""Commands sent while the gateway reconnects, and a flood of them, against a real mosquitto:
every one is carried out and answered."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import aiomqtt

from fcmaster.adapters.mqtt import MqttAdapter
from fcmaster.adapters.settings import MqttSettings
from tests.integration.mosquitto import Broker, Recorder
from tests.integration.mqtt_gateway import FakeGateway

LIMIT_S = 60.0
RESULTS = "fcmaster/+/+/command/result"
DURING_GAP = 30
FLOOD = 10_000


async def test_commands_sent_before_the_gateway_is_back_are_carried_out(tmp_path: Path) -> None:
    broker = Broker(tmp_path, persistence=True)  # keeps sessions across its restart
    await broker.start()
    gateway = FakeGateway()
    # Retries 1-2 s apart: the broker is back well before the gateway tries again.
    settings = MqttSettings(url=broker.url, reconnect_min_s=2.0, reconnect_max_s=2.0,
                            commands=True, trust_broker=True)  # fmt: skip
    try:
        async with asyncio.timeout(LIMIT_S), MqttAdapter(settings, gateway) as adapter:
            await adapter.connected.wait()
            await broker.stop(graceful=True)
            await broker.start()
            async with Recorder(broker, RESULTS, identifier="plant", clean=False) as plant:
                for n in range(DURING_GAP):
                    command = {"id": n, "action": "stop"}
                    await plant.publish("fcmaster/line1/pump-1/command", json.dumps(command))
                assert adapter.connections == 1  # all of them sent while the gateway was away
                await plant.wait_count(RESULTS, DURING_GAP)
                assert sorted(r["id"] for r in plant.json_on(RESULTS)) == list(range(DURING_GAP))
                assert {r["outcome"] for r in plant.json_on(RESULTS)} == {"done"}
            assert len(gateway.executed) == DURING_GAP
    finally:
        await broker.stop()


async def test_a_flood_of_commands_is_taken_in_whole(tmp_path: Path) -> None:
    broker = Broker(tmp_path)  # mosquitto's defaults: 1000 messages queued per client
    await broker.start()
    gateway = FakeGateway()
    settings = MqttSettings(url=broker.url, commands=True, trust_broker=True)
    try:
        async with asyncio.timeout(LIMIT_S * 2), MqttAdapter(settings, gateway) as adapter:
            await adapter.connected.wait()
            async with aiomqtt.Client(broker.host, broker.port, identifier="flood") as plant:
                plant.pending_calls_threshold = 501  # it warns past this many

                async def send(n: int) -> None:
                    command = json.dumps({"id": n, "action": "set_reference", "reference_pct": 1})
                    await plant.publish("fcmaster/line1/pump-1/command", command, qos=1)

                for first in range(0, FLOOD, 500):  # as fast as the broker takes them
                    await asyncio.gather(*(send(n) for n in range(first, first + 500)))
            while len(gateway.executed) < FLOOD:
                before = len(gateway.executed)
                await asyncio.sleep(2.0)
                assert len(gateway.executed) > before, f"stuck at {before} of {FLOOD}"
            await asyncio.sleep(0.5)  # time for a duplicate to show up, if any
            assert len(gateway.executed) == FLOOD
            assert "outgoing messages are being dropped" not in broker.log.read_text()
    finally:
        await broker.stop()
