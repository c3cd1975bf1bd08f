"""State, availability, events and the gateway's status on a real broker."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from fcmaster.adapters.mqtt import MqttAdapter
from fcmaster.adapters.settings import MqttSettings
from fcmaster.config import parse
from fcmaster.service import Service
from tests.fakes import WallShiftedClock
from tests.integration.mosquitto import Broker, Recorder, payload_text
from tests.integration.mqtt_gateway import FakeGateway

LIMIT_S = 20.0
STATE_KEYS = {
    "name", "bus", "address", "protocol", "online", "control", "running", "fault", "warning",
    "direction", "at_reference", "output_frequency_hz", "output_frequency_updated_at",
    "reference_pct", "status_word", "status_bits",
    "values", "alarms", "warnings", "updated_at",
}  # fmt: skip
SIM_CONFIG = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    drives:
      - {name: pump-1, address: 1, control: bus}
      - {name: fan-2, address: 2}
      - {name: fan-3, address: 3}
  - name: line2
    port: sim://line2
    baudrate: 115200
    drives:
      - {name: mixer-4, address: 4}
mqtt:
  url: URL
  reconnect_min_s: 0.05
  reconnect_max_s: 0.5
"""
DRIVES = {"line1": ("pump-1", "fan-2", "fan-3"), "line2": ("mixer-4",)}


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with Broker(tmp_path) as running:
        yield running


async def settle() -> None:
    """Let the bridge's pump take what the hub has filed."""
    for _ in range(20):
        await asyncio.sleep(0)


def model(broker: Broker, **overrides: Any) -> MqttSettings:
    settings: dict[str, Any] = {"url": broker.url, "reconnect_min_s": 0.05}
    return MqttSettings(**{**settings, **overrides})


async def test_every_drive_has_retained_state_and_availability(broker: Broker) -> None:
    service = Service(parse(SIM_CONFIG.replace("URL", broker.url)))
    async with asyncio.timeout(LIMIT_S):
        running = asyncio.create_task(service.run(install_signals=False))
        async with Recorder(broker, "fcmaster/#") as watcher:
            for bus, drives in DRIVES.items():
                for drive in drives:
                    await watcher.wait(
                        f"fcmaster/{bus}/{drive}/availability",
                        lambda m: payload_text(m) == "online",
                    )
                    await watcher.wait_json(f"fcmaster/{bus}/{drive}/state", lambda s: s["online"])
        # a newcomer finds all of it retained, with the gateway's status
        async with Recorder(broker, "fcmaster/#") as late:
            await late.wait("fcmaster/status", lambda m: payload_text(m) == "online")
            for bus, drives in DRIVES.items():
                for drive in drives:
                    state = await late.wait_json(f"fcmaster/{bus}/{drive}/state")
                    assert set(state) == STATE_KEYS
                    assert (state["bus"], state["name"], state["online"]) == (bus, drive, True)
                    assert state["values"]["16-13"]["unit"] == "Hz"
                    available = await late.wait(f"fcmaster/{bus}/{drive}/availability")
                    assert available.retain
                    assert payload_text(available) == "online"
            assert all(m.retain for m in late.on("fcmaster/+/+/state"))
            service.stop()
            await running
            # a clean stop says so: the gateway and its drives go offline
            await late.wait("fcmaster/status", lambda m: payload_text(m) == "offline")
            for bus, drives in DRIVES.items():
                for drive in drives:
                    await late.wait(
                        f"fcmaster/{bus}/{drive}/availability",
                        lambda m: payload_text(m) == "offline",
                    )


async def test_state_goes_out_on_significant_change_only_and_on_the_heartbeat(
    broker: Broker,
) -> None:
    gateway = FakeGateway()
    gateway.reply("pump-1", hz=10.0, value=("16-14", 4.0, "A"))
    topic = "fcmaster/line1/pump-1/state"
    async with asyncio.timeout(LIMIT_S), Recorder(broker, topic) as watcher:
        adapter = MqttAdapter(model(broker, deadband_pct=5.0, heartbeat_s=3600), gateway)
        async with adapter:
            await watcher.wait_json(topic, lambda s: s["output_frequency_hz"] == 10.0)
            first = len(watcher.messages)
            # one at a time: the hub would conflate them for a subscriber that is behind
            for frequency_hz, current_a, running in [
                (11.0, 4.1, False),  # 2 % of 50 Hz, 2.4 % of 4.1 A: within the band
                (12.4, 4.1, False),  # 4.8 % of 50 Hz since the state sent: still within
                (12.4, 4.3, False),  # 7 % of 4.3 A: sent
                (12.4, 4.3, True),  # a discrete change: sent
            ]:
                gateway.reply("pump-1", hz=frequency_hz, value=("16-14", current_a, "A"),
                              running=running)  # fmt: skip
                await settle()
            state = await watcher.wait_json(topic, lambda s: s["running"], start=first)
            sent = watcher.json_on(topic)[first:]
            assert [(s["output_frequency_hz"], s["values"]["16-14"]["value"]) for s in sent] == [
                (12.4, 4.3),
                (12.4, 4.3),
            ]
            assert state["running"]

    heartbeat = MqttAdapter(model(broker, heartbeat_s=0.2), gateway)
    async with asyncio.timeout(LIMIT_S), Recorder(broker, topic) as watcher, heartbeat:
        for _ in range(3):  # no change at all, and still the state keeps coming
            await watcher.wait(topic, start=len(watcher.messages))


async def test_alarm_and_availability_changes_are_events(broker: Broker) -> None:
    gateway = FakeGateway()
    gateway.reply("fan-2")
    base = "fcmaster/line1/fan-2"
    async with (
        asyncio.timeout(LIMIT_S),
        Recorder(broker, f"{base}/#") as watcher,
        MqttAdapter(model(broker), gateway) as adapter,
    ):
        await adapter.connected.wait()
        await watcher.wait(f"{base}/availability", lambda m: payload_text(m) == "online")
        gateway.reply("fan-2", alarms=((14, "Earth fault"),))
        gateway.reply("fan-2", alarms=())
        gateway.offline("fan-2")
        await watcher.wait(f"{base}/availability", lambda m: payload_text(m) == "offline")
        await watcher.wait_count(f"{base}/event", 3)
        events = watcher.json_on(f"{base}/event")
        assert [(e["event"], e.get("code"), e["bus"], e["drive"]) for e in events] == [
            ("alarm_raised", 14, "line1", "fan-2"),
            ("alarm_cleared", 14, "line1", "fan-2"),
            ("offline", None, "line1", "fan-2"),
        ]
        assert events[0]["text"] == "Earth fault"
        assert all(e["at"].endswith("Z") for e in events)
        assert not any(m.retain for m in watcher.on(f"{base}/event"))
        state = watcher.json_on(f"{base}/state")[-1]
        assert state["online"] is False


async def test_events_are_stamped_by_the_gateways_clock(broker: Broker) -> None:
    wall = 1_790_000_009.75  # `date -u -d @1790000009.75`: 2026-09-21T14:13:29.750Z
    gateway = FakeGateway(clock=WallShiftedClock(lambda: wall))
    gateway.reply("fan-2")
    base = "fcmaster/line1/fan-2"
    async with (
        asyncio.timeout(LIMIT_S),
        Recorder(broker, f"{base}/event") as watcher,
        MqttAdapter(model(broker), gateway) as adapter,
    ):
        await adapter.connected.wait()
        gateway.reply("fan-2", alarms=((14, "Earth fault"),))
        await watcher.wait_count(f"{base}/event", 1)
        (event,) = watcher.json_on(f"{base}/event")
        assert (event["event"], event["at"]) == ("alarm_raised", "2026-09-21T14:13:29.750Z")
