"""Home Assistant MQTT discovery: drives as devices, and entities that work as commands."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest

from fcmaster.adapters.mqtt import MqttAdapter
from fcmaster.adapters.settings import MqttSettings
from tests.integration.mosquitto import Broker, Recorder, payload_text
from tests.integration.mqtt_gateway import FakeGateway

LIMIT_S = 20.0
PUMP = "homeassistant/+/fcmaster_line1_pump-1/+/config"
FAN = "homeassistant/+/fcmaster_line1_fan-2/+/config"


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with Broker(tmp_path) as running:
        yield running


def entities(client: Recorder, pattern: str) -> dict[str, Any]:
    """``component/object`` → config, from what was received on ``pattern``."""
    found = {}
    for message in client.on(pattern):
        _, component, _, object_id, _ = message.topic.value.split("/")
        found[f"{component}/{object_id}"] = json.loads(payload_text(message))
    return found


async def test_each_drive_is_a_device_and_only_bus_drives_get_controls(broker: Broker) -> None:
    gateway = FakeGateway()
    settings = MqttSettings(
        url=broker.url, discovery=True, reconnect_min_s=0.05, commands=True, trust_broker=True
    )
    async with (
        asyncio.timeout(LIMIT_S),
        Recorder(broker, "homeassistant/#", "fcmaster/#") as ha,
        MqttAdapter(settings, gateway) as adapter,
    ):
        await adapter.connected.wait()
        await ha.wait("homeassistant/number/fcmaster_line1_pump-1/reference_hz/config")
        await ha.wait("homeassistant/binary_sensor/fcmaster_line1_fan-2/warning/config")
        gateway.reply("pump-1", hz=20.0, value=("16-14", 3.2, "A"))
        current = await ha.wait_json("homeassistant/sensor/+/value_16-14/config")

        pump, fan = entities(ha, PUMP), entities(ha, FAN)
        assert set(fan) == {
                "sensor/output_frequency", "sensor/reference", "binary_sensor/running",
                "binary_sensor/fault", "binary_sensor/warning",
            }  # fmt: skip
        assert set(pump) == set(fan) | {
            "button/start",
            "button/stop",
            "number/reference_hz",
            "sensor/value_16-14",
        }
        async with Recorder(broker, "homeassistant/#") as late:  # they are retained
            assert all(m.retain for m in await late.wait_count(PUMP, len(pump)))
        frequency = pump["sensor/output_frequency"]
        assert frequency["state_topic"] == "fcmaster/line1/pump-1/state"
        assert (frequency["device_class"], frequency["unit_of_measurement"]) == ("frequency", "Hz")
        assert frequency["device"]["identifiers"] == ["fcmaster_line1_pump-1"]
        assert frequency["device"]["manufacturer"] == "Danfoss"
        assert [a["topic"] for a in frequency["availability"]] == [
            "fcmaster/status",
            "fcmaster/line1/pump-1/availability",
        ]
        assert (current["device_class"], current["unit_of_measurement"]) == ("current", "A")
        assert len({config["unique_id"] for config in [*pump.values(), *fan.values()]}) == 14

        # the controls speak the command JSON: press start, set 30 Hz
        start = pump["button/start"]
        await ha.publish(start["command_topic"], start["payload_press"])
        reference = pump["number/reference_hz"]
        assert (reference["min"], reference["max"]) == (0.0, 50.0)
        rendered = reference["command_template"].replace("{{ value }}", "30")
        await ha.publish(reference["command_topic"], rendered)
        await ha.wait_count("fcmaster/line1/pump-1/command/result", 2)
    assert [(c.action.value, c.reference_pct) for _, c in gateway.executed] == [
        ("start", None),
        ("set_reference", 60.0),
    ]
    assert {r["outcome"] for r in ha.json_on("fcmaster/+/+/command/result")} == {"done"}
