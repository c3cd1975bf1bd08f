"""The broker goes away and comes back: reconnect, republish, and every command answered."""

from __future__ import annotations

import asyncio
import json
import sys
from pathlib import Path

from fcmaster.adapters.mqtt import MqttAdapter
from fcmaster.adapters.settings import MqttSettings
from fcmaster.config import parse
from fcmaster.service import Service
from tests.integration.mosquitto import Broker, Recorder, payload_text
from tests.integration.mqtt_gateway import FakeGateway, Gate

LIMIT_S = 30.0
SIM_CONFIG = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    drives:
      - {name: pump-1, address: 1, control: bus}
      - {name: fan-2, address: 2}
mqtt: {url: URL, reconnect_min_s: 0.05, reconnect_max_s: 0.2, commands: true,
       trust_broker: true}
"""
DRIVES = ("pump-1", "fan-2")


async def test_after_a_broker_restart_the_gateway_republishes_and_takes_commands(
    tmp_path: Path,
) -> None:
    broker = Broker(tmp_path)  # no persistence: the restarted broker has forgotten everything
    await broker.start()
    service = Service(parse(SIM_CONFIG.replace("URL", broker.url)))
    try:
        async with asyncio.timeout(LIMIT_S):
            running = asyncio.create_task(service.run(install_signals=False))
            async with Recorder(broker, "fcmaster/#") as before:
                for drive in DRIVES:
                    await before.wait_json(f"fcmaster/line1/{drive}/state", lambda s: s["online"])
            await broker.stop()  # SIGKILL: no goodbye to anyone
            await asyncio.sleep(0.3)  # the gateway fails to reconnect a few times
            await broker.start()
            async with Recorder(broker, "fcmaster/#") as after:
                await after.wait("fcmaster/status", lambda m: payload_text(m) == "online")
                for drive in DRIVES:
                    state = await after.wait_json(f"fcmaster/line1/{drive}/state")
                    assert state["online"]
                    available = await after.wait(f"fcmaster/line1/{drive}/availability")
                    assert payload_text(available) == "online"
                # subscribed again: a command through the new broker is carried out
                result = await after.command(
                    "fcmaster/line1/pump-1/command", {"id": "after", "action": "stop"}
                )
                assert result["outcome"] == "done"
                service.stop()
                await running
    finally:
        await broker.stop()


async def test_no_command_is_left_without_a_result_across_a_broker_restart(
    tmp_path: Path,
) -> None:
    broker = Broker(tmp_path, persistence=True)  # keeps the client's session across a restart
    await broker.start()
    gate = Gate()
    gateway = FakeGateway(respond=gate)
    results = "fcmaster/+/+/command/result"
    try:
        async with asyncio.timeout(LIMIT_S):
            adapter = MqttAdapter(MqttSettings(url=broker.url, reconnect_min_s=0.05, commands=True,
                                            trust_broker=True, reconnect_max_s=0.2),
                                  gateway)  # fmt: skip
            async with adapter:
                await adapter.connected.wait()
                async with Recorder(broker, results, identifier="plant", clean=False) as plant:
                    for command_id, drive in (("early", "pump-1"), ("late", "fan-2")):
                        command = {"id": command_id, "action": "stop"}
                        await plant.publish(f"fcmaster/line1/{drive}/command", json.dumps(command))
                        await gate.arrived.get()  # both are running on their lines now
                await broker.stop(graceful=True)  # saves the plant's session
                gate.release("pump-1", "stop")  # ends while there is no broker
                await asyncio.sleep(0.1)
                await broker.start()
                while adapter.connections < 2:  # noqa: ASYNC110 - no event says "connected again"
                    await asyncio.sleep(0.02)
                gate.release("fan-2", "stop")  # ends after the gateway is back
                async with Recorder(broker, results, identifier="plant", clean=False) as plant:
                    await plant.wait_count(results, 2)
                    await asyncio.sleep(0.2)  # time for a duplicate to show up, if any
                    assert sorted(r["id"] for r in plant.json_on(results)) == ["early", "late"]
                    assert {r["outcome"] for r in plant.json_on(results)} == {"done"}
    finally:
        await broker.stop()


async def test_the_bridge_keeps_trying_while_there_is_no_broker(tmp_path: Path) -> None:
    broker = Broker(tmp_path)  # not started yet
    gateway = FakeGateway()
    gateway.reply("pump-1")
    async with asyncio.timeout(LIMIT_S):
        adapter = MqttAdapter(
            MqttSettings(url=broker.url, reconnect_min_s=0.05, commands=True, trust_broker=True),
            gateway,
        )
        async with adapter:
            await asyncio.sleep(0.3)
            assert not adapter.connected.is_set()
            gateway.reply("pump-1", running=True)  # the line goes on without the broker
            await broker.start()
            try:
                async with Recorder(broker, "fcmaster/#") as client:
                    state = await client.wait_json("fcmaster/line1/pump-1/state")
                    assert state["running"]
            finally:
                await broker.stop()


async def test_a_stalled_broker_does_not_slow_the_line_nor_the_shutdown(tmp_path: Path) -> None:
    broker = Broker(tmp_path)
    await broker.start()
    config = SIM_CONFIG.replace("URL", broker.url).replace("0.2}", "0.2, heartbeat_s: 0.05}")
    service = Service(parse(config))
    try:
        async with asyncio.timeout(LIMIT_S):
            running = asyncio.create_task(service.run(install_signals=False))
            async with Recorder(broker, "fcmaster/#") as client:
                await client.wait_json("fcmaster/line1/pump-1/state", lambda s: s["online"])
            stats = service.masters["line1"].stats
            before = stats.requests
            await asyncio.sleep(0.5)
            free = stats.requests - before
            broker.pause()  # the bridge's publications pile up unanswered
            before = stats.requests
            await asyncio.sleep(0.5)
            stalled = stats.requests - before
            assert stalled > 0.8 * free  # the line polls on as before
            loop = asyncio.get_running_loop()
            stopping = loop.time()
            service.stop()
            await running
            assert loop.time() - stopping < 5.0  # bounded, though the broker never answers
    finally:
        await broker.stop()


async def test_the_will_says_offline_when_the_gateway_dies(tmp_path: Path) -> None:
    broker = Broker(tmp_path)
    config = tmp_path / "gateway.yaml"
    config.write_text(SIM_CONFIG.replace("URL", broker.url))
    async with asyncio.timeout(LIMIT_S), broker, Recorder(broker, "fcmaster/#") as client:
        daemon = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "fcmaster", "run", "--config", str(config),
            stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.DEVNULL,
        )  # fmt: skip
        try:
            await client.wait_json("fcmaster/line1/pump-1/state", lambda s: s["online"])
            await client.wait("fcmaster/status", lambda m: payload_text(m) == "online")
        finally:
            daemon.kill()  # no goodbye: the broker publishes the will
            await daemon.wait()
        await client.wait("fcmaster/status", lambda m: payload_text(m) == "offline")
        async with Recorder(broker, "fcmaster/status") as late:
            status = await late.wait("fcmaster/status")
            assert (payload_text(status), status.retain) == ("offline", True)
