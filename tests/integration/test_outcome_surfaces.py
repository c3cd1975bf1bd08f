"""`superseded` and `unconfirmed` as each surface shows them (DESIGN.md "Commands").

Real parts throughout: the daemon's Service over simulated lines, the HTTP API over a
socket (superseded 409, unconfirmed 504), MQTT through a real mosquitto (the outcome in the
result JSON), and the `fcmaster control` command line against `fcmaster sim` on a pty
(exit 1, the reason on stderr). A drive that answers slowly (400 ms) holds the line with a
read, so two references queued behind it meet in the queue and the older one is replaced
before it reaches the wire, however the machine is loaded.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from fcmaster import config
from fcmaster.service import Service
from tests.integration.daemon_harness import START_S, child, get_json, until
from tests.integration.http_harness import OPERATOR, wait_until_listening
from tests.integration.mosquitto import Broker, Recorder
from tests.integration.ports import free_port

LIMIT_S = 30.0
LINE = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    timeout_s: 1.0
    drives:
      - {name: pump-1, address: 1, control: bus}
      - {name: slow, address: 2}
      - {name: local, address: 3, control: bus}
      - {name: interlocked, address: 4, control: bus, confirm_s: 1.0}
    simulation:
      drives:
        2: {response_delay_ms: 400}
        3: {local: true}
        4: {interlocked: true}
"""
HTTP = """
http:
  listen: 127.0.0.1:PORT
  tokens:
    - {name: ops, role: operator, token: "TOKEN"}
"""
MQTT = "mqtt: {url: URL, reconnect_min_s: 0.05, commands: true, trust_broker: true}\n"


async def _run(service: Service) -> asyncio.Task[None]:
    return asyncio.create_task(service.run(install_signals=False), name="test.service")


async def test_http_answers_superseded_409_and_unconfirmed_504() -> None:
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    token = OPERATOR["Authorization"].split()[1]
    service = Service(config.parse(LINE + HTTP.replace("PORT", str(port)).replace("TOKEN", token)))
    running = await _run(service)
    try:
        await wait_until_listening(url)
        async with (
            asyncio.timeout(LIMIT_S),
            httpx.AsyncClient(base_url=url, timeout=20, headers=OPERATOR) as client,
        ):

            async def post(drive: str, command: dict[str, Any]) -> httpx.Response:
                return await client.post(f"/api/v1/drives/{drive}/commands", json=command)

            async def slow_online() -> bool:
                drive = await get_json(client, "/api/v1/drives/slow")
                return bool(drive["online"])

            await until(slow_online, "the slow drive online")
            hold = asyncio.create_task(post("slow", {"action": "read", "parameter": "16-13"}))
            await asyncio.sleep(0.05)  # the read is queued first: the line is held by it
            older = asyncio.create_task(
                post("pump-1", {"action": "set_reference", "frequency_hz": 10})
            )
            await asyncio.sleep(0.05)
            newer = await post("pump-1", {"action": "set_reference", "frequency_hz": 20})
            replaced = await older
            assert (await hold).status_code == 200
            assert newer.status_code == 200
            assert newer.json()["outcome"] == "done"
            assert replaced.status_code == 409
            assert replaced.json()["outcome"] == "superseded"
            assert "set_reference 40 %" in replaced.json()["reason"]  # names the newer one

            local = await post("local", {"action": "start", "frequency_hz": 20})
            assert (local.status_code, local.json()["outcome"]) == (504, "unconfirmed")
            assert "local operation" in local.json()["reason"]
            ignored = await post("interlocked", {"action": "start", "frequency_hz": 20})
            assert (ignored.status_code, ignored.json()["outcome"]) == (504, "unconfirmed")
            assert ignored.json()["reason"].startswith("not running after 1 s")
    finally:
        service.stop()
        async with asyncio.timeout(10):
            await running


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with Broker(tmp_path) as started:
        yield started


async def test_mqtt_results_carry_superseded_and_unconfirmed(broker: Broker) -> None:
    service = Service(config.parse(LINE + MQTT.replace("URL", broker.url)))
    async with asyncio.timeout(LIMIT_S), Recorder(broker, "fcmaster/#") as client:
        running = await _run(service)
        try:
            await client.wait_json("fcmaster/line1/slow/state", lambda s: s["online"])
            await client.wait("fcmaster/status")
            start = len(client.messages)
            await client.publish(
                "fcmaster/line1/slow/command",
                json.dumps({"id": "hold", "action": "read", "parameter": "16-13"}),
            )
            pump = "fcmaster/line1/pump-1/command"
            for id_, hz in (("older", 10), ("newer", 20)):
                payload = {"id": id_, "action": "set_reference", "frequency_hz": hz}
                await client.publish(pump, json.dumps(payload))
            older = await client.wait_json(
                f"{pump}/result", lambda r: r["id"] == "older", start=start
            )
            newer = await client.wait_json(
                f"{pump}/result", lambda r: r["id"] == "newer", start=start
            )
            assert older["outcome"] == "superseded"
            assert "set_reference 40 %" in older["reason"]
            assert newer["outcome"] == "done"

            local = await client.command(
                "fcmaster/line1/local/command", {"id": "l", "action": "start"}
            )
            assert local["outcome"] == "unconfirmed"
            assert "local operation" in local["reason"]
            ignored = await client.command(
                "fcmaster/line1/interlocked/command", {"id": "i", "action": "start"}
            )
            assert ignored["outcome"] == "unconfirmed"
            assert ignored["reason"].startswith("not running after 1 s")
        finally:
            service.stop()
            await running


CLI_CONFIG = """
buses:
  - name: line1
    port: {port}
    baudrate: 38400
    drives:
      - {{name: local, address: 3, control: bus}}
    simulation:
      drives:
        3: {{local: true}}
"""


async def test_the_command_line_fails_an_unconfirmed_start_with_its_reason(tmp_path: Path) -> None:
    link = tmp_path / "ttyLINE1"
    plant = tmp_path / "plant.yaml"
    plant.write_text(CLI_CONFIG.format(port=link))
    async with child("sim", "--config", str(plant), log=tmp_path / "sim.log") as sim:
        assert (await sim.readline()).split()[0] == "line1"
        args = ("control", "--port", str(link), "--baudrate", "38400", "--address", "3")
        async with child(*args, "start", "--frequency", "20", log=tmp_path / "cli.log") as cli:
            code = await asyncio.wait_for(cli.process.wait(), START_S)
        stderr = (tmp_path / "cli.log").read_text()
        assert code == 1, stderr  # the drive did not do it: exit 1, as for a timeout
        assert "fcmaster control: start:" in stderr
        assert "local operation" in stderr
        assert (await sim.stop())[0] == 0
