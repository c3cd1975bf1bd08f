"""The demo fleet's stream carries changes, not polls.

The demo config runs in a real Service (its simulated lines, the HTTP adapter on a free
port), and a WebSocket client reads ``/api/v1/stream`` as the dashboard does. The demo's
drives run steadily, so most of its ~150 replies a second change nothing a subscriber can
see: none of them may reach the stream, except the heartbeat that repeats a drive's state
every ``HEARTBEAT_S`` with its fresh times.
"""

from __future__ import annotations

import asyncio
import itertools
import json
from datetime import datetime
from typing import Any

from websockets.asyncio.client import connect

from fcmaster import config
from fcmaster.cli import DEMO_CONFIG
from fcmaster.service import Service
from fcmaster.state import HEARTBEAT_S
from fcmaster.subcommands.daemon import with_http_listen
from tests.integration.http_harness import wait_until_listening
from tests.integration.ports import free_port

WATCH_S = 2.5 * HEARTBEAT_S
TIMES = ("updated_at", "output_frequency_updated_at")


def _seen(drive: dict[str, Any]) -> dict[str, Any]:
    """What a subscriber can see of a state, without the times it was read."""
    out = {k: v for k, v in drive.items() if k not in TIMES}
    out["values"] = {
        name: {k: v for k, v in value.items() if k != "updated_at"}
        for name, value in drive["values"].items()
    }
    return out


def _at(drive: dict[str, Any]) -> float:
    return datetime.fromisoformat(drive["updated_at"]).timestamp()


async def test_with_the_demo_steady_no_update_repeats_a_state_before_the_heartbeat() -> None:
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    service = Service(with_http_listen(config.load(DEMO_CONFIG), f"127.0.0.1:{port}"), demo=True)
    task = asyncio.create_task(service.run(install_signals=False), name="test.demo")
    received: dict[str, list[dict[str, Any]]] = {}
    replies_before = 0
    try:
        await wait_until_listening(url, timeout_s=30)
        async with connect(f"ws://127.0.0.1:{port}/api/v1/stream") as ws:
            snapshot = json.loads(await ws.recv())
            assert snapshot["type"] == "snapshot"
            # Steady: past adoption, the first condition reads and the watchdog audit, whose
            # verdicts are published as they are found; what the stream carried until then
            # is not the steady state this test watches.
            await service.hub.wait_for(
                lambda: all(
                    drive.watchdog is not None
                    for drive in service.fleet.snapshot()
                    if drive.control == "bus"
                ),
                timeout_s=60,
            )
            await asyncio.sleep(1.0)
            while True:
                try:
                    async with asyncio.timeout(0.05):
                        await ws.recv()
                except TimeoutError:
                    break
            replies_before = sum(line.stats.get("replies", 0) for line in service.lines())
            loop = asyncio.get_running_loop()
            until = loop.time() + WATCH_S
            while (left := until - loop.time()) > 0:
                try:
                    async with asyncio.timeout(left):
                        message = json.loads(await ws.recv())
                except TimeoutError:
                    break
                if message["type"] == "drive":
                    received.setdefault(message["drive"]["name"], []).append(message)
            replies = sum(line.stats.get("replies", 0) for line in service.lines()) - replies_before
    finally:
        service.stop()
        async with asyncio.timeout(10):
            await task

    updates = sum(len(m) for m in received.values())
    assert replies > 20 * updates  # the stream is a small fraction of the polls
    heartbeats = 0
    for name, messages in received.items():
        for earlier, later in itertools.pairwise(messages):
            before, after = earlier["drive"], later["drive"]
            if _seen(before) == _seen(after):
                heartbeats += 1
                assert later["changed"] == [], name
                gap_s = _at(after) - _at(before)
                assert gap_s >= HEARTBEAT_S - 0.002, (name, gap_s)  # ms-rounded times
            else:
                assert later["changed"], (name, before, after)
    assert heartbeats >= 8  # the steady drives did repeat, on the heartbeat
