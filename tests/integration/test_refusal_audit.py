"""Commands refused before they reach a line are audited like every ended command.

On each surface — HTTP, MQTT (a real mosquitto), Modbus TCP (the real daemon over simulated
lines) — a command refused for what it says (beyond the drive's configured limits,
malformed, no such drive, no such action code) leaves exactly one ``command.completed`` line
with who asked, the drive, the action, the values as given, the outcome and the reason.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, MutableMapping
from pathlib import Path
from typing import Any

import httpx
import pytest
from structlog.testing import capture_logs

from fcmaster.adapters.mqtt import MqttAdapter
from fcmaster.adapters.settings import MqttSettings
from tests.integration.gateway_double import FakeGateway
from tests.integration.http_harness import OPERATOR, serving
from tests.integration.modbus_client import Client, ModbusError
from tests.integration.modbus_harness import plant
from tests.integration.mosquitto import Broker, Recorder
from tests.integration.mqtt_gateway import FakeGateway as MqttGateway

LIMIT_S = 30.0
BEYOND = "50.0000001 Hz is beyond pump-1's configured limit of 50 Hz"


def audits(logs: list[MutableMapping[str, Any]]) -> list[dict[str, Any]]:
    """The audit lines, without the logger's own key."""
    return [
        {k: v for k, v in e.items() if k != "log_level"}
        for e in logs
        if e["event"] == "command.completed"
    ]


# -- HTTP --------------------------------------------------------------------------------------


@pytest.fixture
async def http() -> AsyncIterator[tuple[FakeGateway, httpx.AsyncClient]]:
    gateway = FakeGateway()
    async with serving(gateway) as adapter, httpx.AsyncClient(base_url=adapter.url) as client:
        yield gateway, client


async def test_http_a_reference_beyond_the_limit_is_audited_with_its_frequency(
    http: tuple[FakeGateway, httpx.AsyncClient],
) -> None:
    gateway, client = http
    with capture_logs() as logs:
        response = await client.post(
            "/api/v1/drives/pump-1/commands",
            json={"action": "set_reference", "frequency_hz": 50.0000001},
            headers=OPERATOR,
        )
    assert response.status_code == 403
    assert gateway.executed == []
    assert audits(logs) == [
        {
            "event": "command.completed",
            "actor": "ops",
            "drive": "pump-1",
            "command": "set_reference",
            "frequency_hz": 50.0000001,
            "outcome": "not_allowed",
            "reason": BEYOND,
            "bus": "line1",
        }
    ]


async def test_http_a_malformed_command_and_a_parameter_write_are_audited_as_given(
    http: tuple[FakeGateway, httpx.AsyncClient],
) -> None:
    _, client = http
    with capture_logs() as logs:
        command = await client.post(
            "/api/v1/drives/pump-1/commands",
            json={"action": "start", "frequency_hz": "fast"},
            headers=OPERATOR,
        )
        write = await client.put(
            "/api/v1/drives/pump-1/parameters/3-41", json={"value": [1, 2]}, headers=OPERATOR
        )
    assert (command.status_code, write.status_code) == (422, 422)
    first, second = audits(logs)
    assert (first["actor"], first["drive"], first["command"]) == ("ops", "pump-1", "start")
    assert (first["frequency_hz"], first["outcome"]) == ("fast", "invalid")
    assert first["reason"] == command.json()["reason"]
    assert (second["command"], second["parameter"], second["value"]) == ("write", "3-41", "[1, 2]")
    assert (second["outcome"], second["reason"]) == ("invalid", write.json()["reason"])


async def test_http_a_command_for_no_such_drive_is_audited(
    http: tuple[FakeGateway, httpx.AsyncClient],
) -> None:
    _, client = http
    with capture_logs() as logs:
        response = await client.post(
            "/api/v1/drives/pump-9/commands",
            json={"action": "start", "frequency_hz": 20},
            headers=OPERATOR,
        )
    assert response.status_code == 404
    [audit] = audits(logs)
    assert (audit["actor"], audit["drive"], audit["command"]) == ("ops", "pump-9", "start")
    assert (audit["frequency_hz"], audit["outcome"]) == (20, "invalid")
    assert audit["reason"] == "no drive called 'pump-9'"


# -- MQTT --------------------------------------------------------------------------------------


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with Broker(tmp_path) as running:
        yield running


async def test_mqtt_refused_commands_are_audited_with_their_values(broker: Broker) -> None:
    gateway = MqttGateway()
    settings = MqttSettings(url=broker.url, reconnect_min_s=0.05, commands=True, trust_broker=True)
    pump = "fcmaster/line1/pump-1/command"
    with capture_logs() as logs:
        async with (
            asyncio.timeout(LIMIT_S),
            Recorder(broker, "fcmaster/#") as client,
            MqttAdapter(settings, gateway) as adapter,
        ):
            await adapter.connected.wait()
            beyond = await client.command(
                pump, {"id": 5, "action": "set_reference", "frequency_hz": 50.0000001}
            )
            missing = await client.command(pump, {"id": 6, "action": "write", "parameter": "3-41"})
    assert (beyond["outcome"], missing["outcome"]) == ("not_allowed", "invalid")
    assert gateway.executed == []
    first, second = audits(logs)
    assert first == {
        "event": "command.completed",
        "actor": adapter.actor,
        "drive": "pump-1",
        "command": "set_reference",
        "frequency_hz": 50.0000001,
        "outcome": "not_allowed",
        "reason": BEYOND,
        "bus": "line1",
        "command_id": 5,
    }
    assert (second["command"], second["parameter"], second["command_id"]) == ("write", "3-41", 6)
    assert (second["outcome"], second["reason"]) == ("invalid", missing["reason"])


# -- Modbus TCP --------------------------------------------------------------------------------


async def test_modbus_refused_writes_are_audited_with_their_values() -> None:
    with capture_logs() as logs:
        async with (
            asyncio.timeout(LIMIT_S),
            plant() as running,
            Client("127.0.0.1", running.port) as client,
        ):
            with pytest.raises(ModbusError) as beyond:
                await client.write_single(1, 1, 4500)  # 45.00 Hz on a drive limited to 40 Hz
            with pytest.raises(ModbusError) as unknown:
                await client.write_single(1, 0, 9)  # no action has code 9
    assert (beyond.value.code, unknown.value.code) == (0x03, 0x03)
    first, second = audits(logs)
    assert first["actor"].startswith("modbus:")
    assert (first["drive"], first["bus"], first["command"]) == ("pump-1", "line1", "set_reference")
    assert (first["frequency_hz"], first["outcome"]) == (45.0, "not_allowed")
    assert first["reason"] == "45 Hz is beyond pump-1's configured limit of 40 Hz"
    assert (second["command"], second["value"], second["outcome"]) == ("-", 9, "invalid")
    assert second["reason"].startswith("command 9 is no action code (1 start, 2 stop")
