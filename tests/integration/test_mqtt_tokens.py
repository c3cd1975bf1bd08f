"""Who may command over MQTT, against a real broker: off by default, then operator tokens.

With ``mqtt.commands: true`` a payload carries ``"token"``, an operator token of
``http.tokens``; its name is the audit's actor. Without one (or with a viewer's, or an
unknown one) the command is ``not_allowed`` and reaches no line; the secret is never logged.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
from structlog.testing import capture_logs

from fcmaster.adapters.mqtt import MqttAdapter
from fcmaster.adapters.settings import MqttSettings
from fcmaster.config import parse
from fcmaster.errors import ConfigError
from fcmaster.service import Service
from tests.integration.mosquitto import Broker, Recorder
from tests.integration.mqtt_gateway import FakeGateway

LIMIT_S = 20.0
PUMP = "fcmaster/line1/pump-1/command"
OPERATOR = "operator-secret-0123456789"
VIEWER = "viewer-secret-0123456789ab"
TOKENS = (("ops", "operator", OPERATOR), ("scada", "viewer", VIEWER))


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with Broker(tmp_path) as running:
        yield running


async def _one(
    broker: Broker, model: MqttSettings, payload: dict[str, Any]
) -> tuple[Any, Any, Any]:
    gateway = FakeGateway()
    async with (
        asyncio.timeout(LIMIT_S),
        Recorder(broker, "fcmaster/#") as client,
        MqttAdapter(model, gateway, tokens=TOKENS) as adapter,
    ):
        await adapter.connected.wait()
        with capture_logs() as logs:
            result = await client.command(PUMP, payload)
    return result, gateway.executed, logs


async def test_commands_are_off_unless_switched_on(broker: Broker) -> None:
    model = MqttSettings(url=broker.url, reconnect_min_s=0.05)
    assert model.commands is False
    result, executed, _ = await _one(broker, model, {"id": 1, "action": "start", "token": OPERATOR})
    assert (result["id"], result["outcome"]) == (1, "not_allowed")
    assert "mqtt.commands" in result["reason"]
    assert executed == []


@pytest.mark.parametrize(
    ("token", "reason"),
    [
        (None, '"token"'),
        ("", '"token"'),
        (12345, '"token"'),
        ("not-a-known-token-at-all", "not recognised"),
        (VIEWER, "scada may only read"),
    ],
    ids=["missing", "empty", "not-text", "unknown", "viewer"],
)
async def test_a_command_without_an_operator_token_is_not_allowed(
    broker: Broker, token: Any, reason: str
) -> None:
    model = MqttSettings(url=broker.url, reconnect_min_s=0.05, commands=True)
    payload: dict[str, Any] = {"id": "c", "action": "start", "frequency_hz": 20}
    if token is not None:
        payload["token"] = token
    result, executed, logs = await _one(broker, model, payload)
    assert (result["id"], result["outcome"]) == ("c", "not_allowed")
    assert reason in result["reason"]
    assert executed == []
    (audit,) = [e for e in logs if e["event"] == "command.completed"]
    assert audit["outcome"] == "not_allowed"
    assert VIEWER not in json.dumps(result) + repr(logs)


async def test_an_operator_token_lets_the_command_through_in_its_name(broker: Broker) -> None:
    model = MqttSettings(url=broker.url, reconnect_min_s=0.05, commands=True)
    payload = {"id": 7, "action": "set_reference", "frequency_hz": 20, "token": OPERATOR}
    result, executed, logs = await _one(broker, model, payload)
    assert (result["id"], result["outcome"]) == (7, "done")
    [(drive, command)] = executed
    assert (drive, command.actor, command.reference_pct) == ("pump-1", "ops", 40.0)
    assert OPERATOR not in json.dumps(result) + repr(logs)


async def test_trusting_the_broker_takes_commands_without_a_token(broker: Broker) -> None:
    model = MqttSettings(url=broker.url, reconnect_min_s=0.05, commands=True, trust_broker=True)
    result, executed, _ = await _one(broker, model, {"id": 2, "action": "stop"})
    assert result["outcome"] == "done"
    assert executed[0][1].actor.startswith("mqtt:")


SERVICE = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    drives:
      - {name: pump-1, address: 1, control: bus}
http:
  listen: 127.0.0.1:0
  tokens:
    - {name: ops, role: operator, token: OPERATOR}
mqtt: {url: URL, reconnect_min_s: 0.05, commands: true}
"""


async def test_the_daemon_takes_the_tokens_of_http_tokens(broker: Broker) -> None:
    config = parse(SERVICE.replace("URL", broker.url).replace("OPERATOR", OPERATOR))
    service = Service(config)
    async with asyncio.timeout(LIMIT_S), Recorder(broker, "fcmaster/#") as client:
        running = asyncio.create_task(service.run(install_signals=False))
        await client.wait_json("fcmaster/line1/pump-1/state", lambda s: s["online"])
        await client.wait("fcmaster/status")
        with capture_logs() as logs:
            refused = await client.command(PUMP, {"id": "a", "action": "stop"})
            done = await client.command(PUMP, {"id": "b", "action": "stop", "token": OPERATOR})
        service.stop()
        await running
    assert (refused["outcome"], done["outcome"]) == ("not_allowed", "done")
    audits = [e for e in logs if e["event"] == "command.completed" and e.get("outcome") == "done"]
    assert [e["actor"] for e in audits] == ["ops"]


def test_commands_with_tokens_need_an_operator_token_configured() -> None:
    text = "buses: [{name: line1, port: sim://line1}]\nmqtt: {commands: true}\n"
    with pytest.raises(ConfigError) as caught:
        parse(text)
    [(where, why)] = caught.value.problems
    assert where == "mqtt.commands"
    assert "trust_broker" in why
    parse(text.replace("commands: true", "commands: true, trust_broker: true"))


SLOW = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    response_delay_ms: 400
    drives:
      - {name: pump-1, address: 1, control: bus}
      - {name: pump-2, address: 2, control: bus}
      - {name: pump-3, address: 3, control: bus}
    simulation: {response_delay_ms: 300}
mqtt: {url: URL, reconnect_min_s: 0.05, commands: true, trust_broker: true}
on_shutdown: stop
"""


async def test_a_command_in_the_stop_phase_gets_a_cancelled_result(broker: Broker) -> None:
    service = Service(parse(SLOW.replace("URL", broker.url)))
    async with asyncio.timeout(LIMIT_S * 2), Recorder(broker, "fcmaster/#") as client:
        running = asyncio.create_task(service.run(install_signals=False))
        for n in (1, 2, 3):
            await client.wait_json(f"fcmaster/line1/pump-{n}/state", lambda s: s["online"])
        await client.wait("fcmaster/status")
        service.stop()  # three stops at 300 ms each: the stop phase lasts about a second
        result = await client.command(PUMP, {"id": "late", "action": "start"})
        await running
    assert result["outcome"] == "cancelled"
    assert result["reason"] == "fcmaster is shutting down"
