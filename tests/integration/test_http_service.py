"""End to end: the Service builds the HTTP adapter over simulated lines, as `fcmaster run` does."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import httpx
from structlog.testing import capture_logs
from websockets.asyncio.client import connect

from fcmaster import config
from fcmaster.service import Service
from tests.integration.http_harness import OPERATOR, VIEWER, service_config, wait_until_listening
from tests.integration.ports import free_port


@asynccontextmanager
async def running(text: str, url: str) -> AsyncIterator[Service]:
    service = Service(config.parse(text))
    task = asyncio.create_task(service.run(install_signals=False), name="test.service")
    try:
        await wait_until_listening(url)
        yield service
    finally:
        service.stop()
        async with asyncio.timeout(10):
            await task


async def test_a_command_over_http_turns_a_simulated_motor_and_the_stream_shows_it() -> None:
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    with capture_logs() as logs:
        async with (
            running(service_config(port), url),
            httpx.AsyncClient(base_url=url, timeout=10) as client,
            connect(f"ws://127.0.0.1:{port}/api/v1/stream", additional_headers=VIEWER) as ws,
        ):
            response = await client.post(
                "/api/v1/drives/pump-1/commands",
                json={"action": "start", "frequency_hz": 25},
                headers=OPERATOR,
            )
            assert response.status_code == 200, response.text
            assert response.json()["outcome"] == "done"
            async with asyncio.timeout(10):
                while True:
                    message: dict[str, Any] = json.loads(await ws.recv())
                    if message["type"] != "drive" or message["drive"]["name"] != "pump-1":
                        continue
                    drive = message["drive"]
                    if drive["running"] and (drive["output_frequency_hz"] or 0) > 5:
                        break
            assert drive["reference_pct"] == 50.0
            stop = await client.post(
                "/api/v1/drives/pump-1/commands", json={"action": "stop"}, headers=OPERATOR
            )
            assert stop.json()["outcome"] == "done"
    completed = [e for e in logs if e["event"] == "command.completed"]
    assert [(e["actor"], e["command"], e["outcome"]) for e in completed] == [
        ("ops", "start", "done"),
        ("ops", "stop", "done"),
    ]


async def test_limits_monitor_only_drives_and_parameters_through_the_real_planner() -> None:
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    async with (
        running(service_config(port), url),
        httpx.AsyncClient(base_url=url, timeout=10) as client,
    ):
        beyond = await client.post(
            "/api/v1/drives/pump-1/commands",
            json={"action": "set_reference", "frequency_hz": 55},
            headers=OPERATOR,
        )
        assert beyond.status_code == 403
        assert beyond.json()["outcome"] == "not_allowed"
        assert "50 Hz" in beyond.json()["reason"]  # the limit is named
        within = await client.post(
            "/api/v1/drives/pump-2/commands",
            json={"action": "set_reference", "frequency_hz": 55},
            headers=OPERATOR,
        )
        assert within.status_code == 200  # pump-2 may go to 60 Hz

        monitor_only = await client.post(
            "/api/v1/drives/fan-1/commands", json={"action": "start"}, headers=OPERATOR
        )
        assert monitor_only.status_code == 403
        assert "monitor-only" in monitor_only.json()["reason"]

        read = await client.get("/api/v1/drives/pump-1/parameters/16-13", headers=VIEWER)
        assert read.status_code == 200
        assert (read.json()["outcome"], read.json()["unit"]) == ("done", "Hz")
        write = await client.put(
            "/api/v1/drives/pump-1/parameters/3-41", json={"value": 2.5}, headers=OPERATOR
        )
        assert write.status_code == 200
        assert write.json()["value"] == 2.5
        nonsense = await client.get("/api/v1/drives/pump-1/parameters/99-99", headers=VIEWER)
        assert nonsense.status_code == 422
        assert "99-99" in nonsense.json()["reason"]


async def test_buses_and_metrics_come_from_the_running_lines() -> None:
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    async with (
        running(service_config(port), url),
        httpx.AsyncClient(base_url=url, timeout=10) as client,
    ):
        buses = (await client.get("/api/v1/buses", headers=VIEWER)).json()
        assert [(b["name"], b["up"]) for b in buses] == [("line1", True), ("line2", True)]
        assert buses[0]["stats"]["requests"] > 0
        drives = (await client.get("/api/v1/drives", headers=VIEWER)).json()
        assert [d["name"] for d in drives] == ["pump-1", "pump-2", "fan-1", "fan-2"]
        text = (await client.get("/metrics", headers=VIEWER)).text
        assert 'fcmaster_bus_up{bus="line2"} 1' in text
        assert 'fcmaster_drive_online{bus="line1",drive="pump-1"} 1' in text
        assert 'fcmaster_bus_transaction_latency_seconds_bucket{bus="line1",le="+Inf"}' in text


CONFIRMING_CONFIG = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    simulation:
      drives:
        2: {{interlocked: true}}
        3: {{local: true}}
    drives:
      - {{name: runs, address: 1, control: bus}}
      - {{name: interlocked, address: 2, control: bus, confirm_s: 1.5}}
      - {{name: local, address: 3, control: bus}}
http:
  listen: 127.0.0.1:{port}
  tokens:
    - {{name: ops, role: operator, token: "{operator}"}}
"""


async def test_a_start_is_done_only_where_the_simulated_motor_turns() -> None:
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    text = CONFIRMING_CONFIG.format(port=port, operator=OPERATOR["Authorization"].split()[1])
    async with (
        running(text, url),
        httpx.AsyncClient(base_url=url, timeout=10) as client,
    ):
        answers = {}
        with capture_logs() as logs:
            for name in ("runs", "interlocked", "local"):
                answer = await client.post(
                    f"/api/v1/drives/{name}/commands",
                    json={"action": "start", "frequency_hz": 20},
                    headers=OPERATOR,
                )
                answers[name] = (answer.status_code, answer.json()["outcome"])
                if name == "interlocked":
                    assert answer.json()["reason"].startswith("not running after 1.5 s")
                if name == "local":
                    assert "local operation" in answer.json()["reason"]
    assert answers == {
        "runs": (200, "done"),
        "interlocked": (504, "unconfirmed"),
        "local": (504, "unconfirmed"),
    }
    audit = [
        (e["drive"], e["frequency_hz"], e["reference_pct"], e["outcome"])
        for e in logs
        if e["event"] == "command.completed"
    ]
    assert audit == [
        ("runs", 20.0, 40.0, "done"),
        ("interlocked", 20.0, 40.0, "unconfirmed"),
        ("local", 20.0, 40.0, "unconfirmed"),
    ]
