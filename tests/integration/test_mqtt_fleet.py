"""Two gateways, one broker (DESIGN.md "Scaling out"): a client sees and commands both
fleets through the broker alone, without knowing which gateway a drive hangs on."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from fcmaster.config import parse
from fcmaster.service import Service
from tests.integration.mosquitto import Broker, Recorder, payload_text

LIMIT_S = 30.0
GATEWAY = """
buses:
  - name: BUS
    port: sim://BUS
    baudrate: 115200
    drives:
      - {name: BUS-pump, address: 1, control: bus}
      - {name: BUS-fan, address: 2}
mqtt:
  url: URL
  status_topic: fcmaster/gateways/BUS-pc/status
  reconnect_min_s: 0.05
  commands: true
  trust_broker: true
"""


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with Broker(tmp_path) as running:
        yield running


@contextlib.asynccontextmanager
async def gateway(broker: Broker, bus: str) -> AsyncIterator[Service]:
    service = Service(parse(GATEWAY.replace("BUS", bus).replace("URL", broker.url)))
    running = asyncio.create_task(service.run(install_signals=False), name=f"gateway[{bus}]")
    try:
        yield service
    finally:
        service.stop()
        await running


async def test_a_client_commands_drives_on_either_gateway_through_the_broker(
    broker: Broker,
) -> None:
    async with (
        asyncio.timeout(LIMIT_S),
        Recorder(broker, "fcmaster/#") as client,
        gateway(broker, "north"),
        gateway(broker, "south"),
    ):
        for bus in ("north", "south"):
            status = f"fcmaster/gateways/{bus}-pc/status"
            await client.wait(status, lambda m: payload_text(m) == "online")
            for drive in (f"{bus}-pump", f"{bus}-fan"):
                await client.wait_json(f"fcmaster/{bus}/{drive}/state", lambda s: s["online"])

        for bus in ("north", "south"):
            topic = f"fcmaster/{bus}/{bus}-pump/command"
            start = await client.command(topic, {"id": f"{bus}-1", "action": "start",
                                                 "reference_pct": 40})  # fmt: skip
            assert (start["outcome"], start["bus"]) == ("done", bus)
            await client.wait_json(f"fcmaster/{bus}/{bus}-pump/state", lambda s: s["running"])
            stop = await client.command(topic, {"id": f"{bus}-2", "action": "stop"})
            assert stop["outcome"] == "done"
        # a drive nobody has, on a line one gateway owns: that gateway alone answers
        nobody = await client.command("fcmaster/south/ghost/command", {"id": "g", "action": "stop"})
        assert nobody["outcome"] == "invalid"
        await asyncio.sleep(0.2)  # time for a second answer to show up, if there were one
        answers = client.json_on("fcmaster/+/+/command/result")
        assert sorted(a["id"] for a in answers) == ["g", "north-1", "north-2", "south-1", "south-2"]
