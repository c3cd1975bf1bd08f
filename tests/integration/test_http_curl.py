"""The HTTP API as curl calls it: `curl -d` sends a form's Content-Type, and that still works.

curl itself, over a real socket: a command or a parameter write typed without
``-H 'Content-Type: application/json'`` (curl then says ``application/x-www-form-urlencoded``)
is read as the JSON it is; a body declared as something else is refused with a reason that
names the header, and nothing reaches the drive.
"""

from __future__ import annotations

import asyncio
import json
import shutil
from typing import Any

import pytest

from fcmaster.bus.commands import Action
from tests.integration.gateway_double import FakeGateway
from tests.integration.http_harness import OPERATOR_TOKEN, serving

pytestmark = pytest.mark.skipif(shutil.which("curl") is None, reason="needs curl")


async def _curl(*args: str) -> tuple[int, dict[str, Any]]:
    """Run curl; its answer's status and JSON body."""
    process = await asyncio.create_subprocess_exec(
        "curl", "-s", "-w", "\n%{http_code}", "-H", f"Authorization: Bearer {OPERATOR_TOKEN}",
        *args, stdout=asyncio.subprocess.PIPE,
    )  # fmt: skip
    async with asyncio.timeout(20):
        out, _ = await process.communicate()
    body, _, status = out.decode().rpartition("\n")
    return int(status), json.loads(body)


@pytest.mark.parametrize(
    "header",
    [(), ("-H", "Content-Type:"), ("-H", "Content-Type: text/plain")],
    ids=["curl-d-form", "no-content-type", "text-plain"],
)
async def test_a_command_sent_without_the_json_content_type_is_read_as_json(
    header: tuple[str, ...],
) -> None:
    gateway = FakeGateway()
    gateway.reply("pump-1", running=True, hz=30.0)
    async with serving(gateway) as adapter:
        url = f"{adapter.url}/api/v1/drives/pump-1/commands"
        status, body = await _curl(*header, "-d", '{"action": "stop"}', url)
        assert (status, body["outcome"]) == (200, "done")
        status, body = await _curl(
            *header,
            "-X",
            "PUT",
            "-d",
            '{"value": 5}',
            f"{adapter.url}/api/v1/drives/pump-1/parameters/3-41",
        )
        assert status == 200, body
    assert [(drive, command.action) for drive, command in gateway.executed] == [
        ("pump-1", Action.STOP),
        ("pump-1", Action.WRITE),
    ]
    assert gateway.executed[1][1].value == 5


async def test_a_body_of_another_type_is_refused_naming_the_header() -> None:
    gateway = FakeGateway()
    async with serving(gateway) as adapter:
        url = f"{adapter.url}/api/v1/drives/pump-1/commands"
        status, body = await _curl("-H", "Content-Type: application/xml", "-d", "<stop/>", url)
        assert (status, body["outcome"]) == (422, "invalid")
        assert "Content-Type: application/json" in body["reason"]
        assert "application/xml" in body["reason"]
        # a form's body that is not JSON says so, as any bad JSON does
        status, body = await _curl("-d", "action=stop", url)
        assert (status, body["outcome"]) == (422, "invalid")
        assert "not valid JSON" in body["reason"]
    assert gateway.executed == []
