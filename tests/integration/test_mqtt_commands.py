"""Commands through a real broker: one result per command, invalid ones never reach a line."""

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
from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.config import parse
from fcmaster.protocol.codec import DriveError
from fcmaster.service import Service
from tests.integration.mosquitto import Broker, Recorder
from tests.integration.mqtt_gateway import FakeGateway, Gate

LIMIT_S = 20.0
SIM_CONFIG = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    drives:
      - {name: pump-1, address: 1, control: bus, max_frequency_hz: 40}
      - {name: fan-2, address: 2}
mqtt: {url: URL, reconnect_min_s: 0.05, commands: true, trust_broker: true}
"""
PUMP = "fcmaster/line1/pump-1/command"


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with Broker(tmp_path) as running:
        yield running


def model(broker: Broker) -> MqttSettings:
    return MqttSettings(url=broker.url, reconnect_min_s=0.05, commands=True, trust_broker=True)


async def test_commands_reach_the_simulated_drive_and_answer_with_their_id(
    broker: Broker,
) -> None:
    service = Service(parse(SIM_CONFIG.replace("URL", broker.url)))
    async with asyncio.timeout(LIMIT_S), Recorder(broker, "fcmaster/#") as client:
        running = asyncio.create_task(service.run(install_signals=False))
        await client.wait_json("fcmaster/line1/pump-1/state", lambda s: s["online"])
        await client.wait("fcmaster/status")  # the bridge is connected and subscribed

        result = await client.command(PUMP, {"id": "a1", "action": "start", "frequency_hz": 25})
        assert result == {
            "id": "a1", "bus": "line1", "drive": "pump-1", "action": "start",
            "outcome": "done", "reason": "",
        }  # fmt: skip
        state = await client.wait_json(
            "fcmaster/line1/pump-1/state",
            lambda s: s["running"] and s["output_frequency_hz"] > 1.0,
        )
        assert state["reference_pct"] == pytest.approx(50.0)

        read = await client.command(PUMP, {"id": 2, "action": "read", "parameter": "16-13"})
        assert (read["id"], read["outcome"], read["unit"]) == (2, "done", "Hz")
        assert read["value"] > 0

        too_fast = await client.command(PUMP, {"id": "a3", "action": "start", "frequency_hz": 45})
        assert too_fast["outcome"] == "not_allowed"
        monitor = await client.command(
            "fcmaster/line1/fan-2/command", {"id": "a4", "action": "start"}
        )
        assert (monitor["outcome"], monitor["drive"]) == ("not_allowed", "fan-2")
        assert "monitor-only" in monitor["reason"]

        stop = await client.command(PUMP, {"id": "a5", "action": "stop"})
        assert stop["outcome"] == "done"
        service.stop()
        await running


def refused(drive: str, command: Command) -> Any:
    async def answer() -> CommandResult:
        return CommandResult(
            outcome=Outcome.REFUSED, reason="the drive refused", error=DriveError(2, "bad value")
        )

    return answer()


async def timed_out(drive: str, command: Command) -> CommandResult:
    return CommandResult(outcome=Outcome.TIMEOUT, reason="no answer after 2 attempts")


@pytest.mark.parametrize(
    ("handler", "outcome", "error"),
    [(refused, "refused", {"code": 2, "text": "bad value"}), (timed_out, "timeout", None)],
    ids=["refused", "timeout"],
)
async def test_refusals_and_timeouts_come_back_as_results(
    broker: Broker, handler: Any, outcome: str, error: Any
) -> None:
    gateway = FakeGateway(respond=handler)
    async with (
        asyncio.timeout(LIMIT_S),
        Recorder(broker, "fcmaster/#") as client,
        MqttAdapter(model(broker), gateway) as adapter,
    ):
        await adapter.connected.wait()
        result = await client.command(PUMP, {"id": 9, "action": "write", "parameter": "3-41",
                                             "value": 99999})  # fmt: skip
    assert result["outcome"] == outcome
    assert result.get("error") == error
    assert result["reason"]


INVALID = [
    pytest.param("line1/pump-1", b"{oops", None, "not valid JSON", id="malformed-json"),
    pytest.param("line1/pump-1", b"", None, "not valid JSON", id="empty"),
    pytest.param("line1/pump-1", b"\xff\xfe\xfa", None, "not valid JSON", id="not-utf8"),
    pytest.param("line1/pump-1", b"[1, 2]", None, "JSON object", id="not-an-object"),
    pytest.param("line1/pump-1", b"[" * 60000, None, "not valid JSON", id="deeply-nested"),
    pytest.param("line1/pump-1", b'{"id": 1, "action": "stop", "x": "%s"}' % (b"a" * 70000),
                 None, "longer than", id="too-long"),
    pytest.param("line1/pump-1", b'{"action": "stop"}', None, "'id' is missing", id="no-id"),
    pytest.param("line1/pump-1", b'{"id": true, "action": "stop"}', True, "'id' must",
                 id="bool-id"),
    pytest.param("line1/pump-1", b'{"id": "x", "action": "launch"}', "x", "unknown action",
                 id="unknown-action"),
    pytest.param("line1/pump-1", b'{"id": "x", "action": 3}', "x", "'action'", id="action-type"),
    pytest.param("line1/pump-1", b'{"id": "x", "action": "start", "frequency_hz": "fast"}', "x",
                 "finite number", id="wrong-type"),
    pytest.param("line1/pump-1", b'{"id": "x", "action": "start", "frequency_hz": NaN}', None,
                 "NaN is not a JSON number", id="nan"),
    pytest.param("line1/pump-1", b'{"id": "x", "action": "stop", "action": "start"}', None,
                 "duplicated key 'action'", id="duplicated-key"),
    pytest.param("line1/pump-1", b'{"id": "x", "action": "start", "frequency_hz": -40}', "x",
                 "magnitude (≥ 0)", id="negative-frequency"),
    pytest.param("line1/pump-1", b'{"id": "x", "action": "write", "parameter": "3-41", '
                 b'"value": 1e308}', "x", "'value' is beyond", id="huge-value"),
    pytest.param("line1/pump-1", b'{"id": "x", "action": "write", "parameter": "3-41", '
                 b'"value": 1e400}', None, "beyond what a number can hold", id="overflow"),
    pytest.param("line1/pump-1", b'{"id": "x", "action": "stop", "force": 1}', "x",
                 "does not take", id="unknown-key"),
    pytest.param("line1/pump-1", b'{"id": "x", "action": "read"}', "x", "'parameter'",
                 id="read-without-parameter"),
    pytest.param("line1/nobody", b'{"id": "x", "action": "stop"}', "x", "no drive",
                 id="unknown-drive"),
    pytest.param("line2/pump-1", b'{"id": "x", "action": "stop"}', "x", "no drive",
                 id="drive-on-another-bus"),
]  # fmt: skip


@pytest.mark.parametrize(("where", "payload", "command_id", "reason"), INVALID)
async def test_invalid_commands_get_one_invalid_result_and_never_reach_a_line(
    broker: Broker, where: str, payload: bytes, command_id: Any, reason: str
) -> None:
    gateway = FakeGateway()
    topic = f"fcmaster/{where}/command"
    async with (
        asyncio.timeout(LIMIT_S),
        Recorder(broker, "fcmaster/#") as client,
        MqttAdapter(model(broker), gateway) as adapter,
    ):
        await adapter.connected.wait()
        with capture_logs() as logs:
            await client.publish(topic, payload)
            result = await client.wait_json(f"{topic}/result")
            # a valid command after it is answered after it: nothing else came in between
            await client.command(PUMP, {"id": "next", "action": "stop"})
    assert result["id"] == command_id
    assert result["outcome"] == "invalid"
    assert reason in result["reason"]
    assert [c.action.value for _, c in gateway.executed] == ["stop"]  # only the valid one
    assert len(client.on(f"{topic}/result")) == 1 + (topic == PUMP)
    logged = [e for e in logs if e["event"] == "command.completed"]
    assert logged[0]["actor"] == adapter.actor
    assert logged[0]["outcome"] == "invalid"
    assert adapter.actor.startswith("mqtt:")


async def test_a_reference_beyond_the_limit_is_not_allowed_stated_exactly(broker: Broker) -> None:
    gateway = FakeGateway()
    async with (
        asyncio.timeout(LIMIT_S),
        Recorder(broker, "fcmaster/#") as client,
        MqttAdapter(model(broker), gateway) as adapter,
    ):
        await adapter.connected.wait()
        result = await client.command(
            PUMP, {"id": 5, "action": "set_reference", "frequency_hz": 50.0000001}
        )
    assert result["outcome"] == "not_allowed"
    assert result["reason"] == "50.0000001 Hz is beyond pump-1's configured limit of 50 Hz"
    assert gateway.executed == []


async def test_a_slow_read_does_not_hold_up_a_stop_for_another_drive(broker: Broker) -> None:
    gate = Gate()
    gateway = FakeGateway(respond=gate)
    async with (
        asyncio.timeout(LIMIT_S),
        Recorder(broker, "fcmaster/#") as client,
        MqttAdapter(model(broker), gateway) as adapter,
    ):
        await adapter.connected.wait()
        await client.publish(PUMP, json.dumps({"id": "r", "action": "read",
                                               "parameter": "16-13"}))  # fmt: skip
        assert (await gate.arrived.get())[0] == "pump-1"
        gate.release("fan-2", "stop")
        stop = await client.command("fcmaster/line1/fan-2/command", {"id": "s", "action": "stop"})
        assert stop["outcome"] == "done"
        assert client.on(f"{PUMP}/result") == []  # the read is still on its way
        gate.release("pump-1", "read")
        read = await client.wait_json(f"{PUMP}/result")
        assert read["id"] == "r"


async def test_a_retained_command_is_not_run_when_the_broker_replays_it(broker: Broker) -> None:
    gateway = FakeGateway()
    async with asyncio.timeout(LIMIT_S), Recorder(broker, "fcmaster/#") as client:
        await client.publish(PUMP, json.dumps({"id": "old", "action": "start"}), retain=True)
        with capture_logs() as logs:
            async with MqttAdapter(model(broker), gateway) as adapter:
                await adapter.connected.wait()
                await client.command(PUMP, {"id": "new", "action": "stop"})
        await client.publish(PUMP, b"", retain=True)  # clear it
    assert [c.action.value for _, c in gateway.executed] == ["stop"]
    assert [r["id"] for r in client.json_on(f"{PUMP}/result")] == ["new"]
    assert any(e["event"] == "mqtt.retained_command_ignored" for e in logs)
