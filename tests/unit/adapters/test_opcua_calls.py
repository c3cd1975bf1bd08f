"""What the OPC UA adapter makes of a method call: who may, and the command it becomes."""

from __future__ import annotations

import asyncio
import socket
from typing import Any, cast

import pytest
from structlog.testing import capture_logs

from fcmaster.adapters.opcua import OpcuaAdapter, drive_entry, line_entry
from fcmaster.adapters.settings import OpcuaSettings, Token
from fcmaster.bus.commands import Action
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.drive_state import DriveState, Measured
from fcmaster.errors import ConfigError
from fcmaster.opcua.wire import encode
from tests.integration.gateway_double import LINE, FakeGateway

USERS = (Token("scada", "viewer", "v" * 16), Token("ops", "operator", "o" * 16))


def adapter(gateway: FakeGateway, *, commands: bool = True) -> OpcuaAdapter:
    settings = OpcuaSettings(commands=commands, users=USERS)
    return OpcuaAdapter(settings, gateway, lines=(LINE,))


@pytest.mark.parametrize(
    ("user", "commands", "reason"),
    [
        ("scada", True, "scada is no operator"),
        (None, True, "an anonymous session is no operator"),
        ("ghost", True, "ghost is no operator"),
        ("ops", False, "opcua.commands is false"),
    ],
)
async def test_only_operators_command_and_only_when_commands_are_on(
    user: str | None, commands: bool, reason: str
) -> None:
    gateway = FakeGateway()
    with capture_logs() as logs:
        result = await adapter(gateway, commands=commands).execute_call(
            user, "pump-1", {"action": "start"}
        )
    assert result.denied
    assert result.outcome == "not_allowed"
    assert reason in result.reason
    assert gateway.executed == []  # nothing reached a line
    (audited,) = [e for e in logs if e["event"] == "command.completed"]
    assert audited["actor"] == f"opcua:{user or 'anonymous'}"
    assert audited["outcome"] == "not_allowed"


async def test_an_operators_call_is_the_command_with_its_actor() -> None:
    gateway = FakeGateway()
    result = await adapter(gateway).execute_call(
        "ops", "pump-1", {"action": "set_reference", "frequency_hz": 25.0}
    )
    assert (result.outcome, result.denied) == ("done", False)
    ((drive, command),) = gateway.executed
    assert (drive, command.action, command.actor) == ("pump-1", Action.SET_REFERENCE, "opcua:ops")
    assert command.reference_pct == 50.0


async def test_a_reference_beyond_the_limits_is_refused_not_clamped() -> None:
    gateway = FakeGateway()
    result = await adapter(gateway).execute_call(
        "ops", "pump-1", {"action": "set_reference", "frequency_hz": 50.5}
    )
    assert (result.outcome, result.denied) == ("not_allowed", False)
    assert "50.5" in result.reason
    assert gateway.executed == []


async def test_a_call_for_a_drive_that_is_not_there_is_invalid() -> None:
    result = await adapter(FakeGateway()).execute_call("ops", "pump-9", {"action": "stop"})
    assert (result.outcome, result.denied) == ("invalid", False)


def test_the_compact_entry_keeps_each_readings_time() -> None:
    state = DriveState(
        name="pump-1", bus="line1", address=1, protocol="danfoss-fc", control="bus",
        online=True, running=True, output_frequency_hz=40.0, output_frequency_updated_at=5.0,
        updated_at=7.0, status_word=0x0F07, reference_pct=80.0,
        values={"16-14": Measured(3.5, "A", 35, "Motor Current", 6.0)},
    )  # fmt: skip
    entry: dict[str, Any] = drive_entry(state)
    assert entry["f"] == 40.0
    assert entry["f_at"] == 5.0
    assert entry["at"] == 7.0
    assert entry["values"] == {"Motor Current": [3.5, 6.0]}
    assert line_entry("line1", True, {"requests": 3, "utilisation": 0.5}) == {
        "name": "line1", "up": True, "counters": {"Requests": 3},
    }  # fmt: skip


def test_every_drive_of_the_lines_is_in_the_hello() -> None:
    fan = DrivePlan(name="fan-9", address=9)
    line2 = LinePlan(name="line2", port="sim://line2", drives=(fan,))
    hello = OpcuaAdapter(OpcuaSettings(users=USERS), FakeGateway(), lines=(LINE, line2)).hello()
    assert [(d["name"], d["bus"]) for d in hello["drives"]] == [
        ("pump-1", "line1"), ("fan-1", "line1"), ("fan-9", "line2"),
    ]  # fmt: skip
    assert hello["settings"]["users"] == [["scada", "v" * 16], ["ops", "o" * 16]]
    assert hello["settings"]["security"] == list(OpcuaSettings().security)


async def test_a_taken_port_is_refused_at_start_naming_the_key() -> None:
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        settings = OpcuaSettings(listen=f"127.0.0.1:{port}", users=USERS)
        with pytest.raises(ConfigError) as info:
            async with OpcuaAdapter(settings, FakeGateway(), lines=(LINE,)):
                pass
    ((key, reason),) = info.value.problems
    assert key == "opcua.listen"
    assert f"cannot listen on 127.0.0.1:{port}" in reason


async def test_the_servers_sessions_are_kept_as_it_says_them() -> None:
    served = adapter(FakeGateway())
    assert served.status() == {"listen": "127.0.0.1:4840", "up": False, "restarts": 0,
                               "sessions": []}  # fmt: skip
    session = {"user": "scada", "client": "127.0.0.1:50312", "application": "UaExpert",
               "security": "Basic256Sha256:SignAndEncrypt", "since": 1795000000.25}  # fmt: skip
    anonymous = session | {"user": None, "client": "10.0.0.9:40000", "since": 1795000001.0}
    said: list[dict[str, Any]] = [
        {"t": "ready"},
        {"t": "sessions", "sessions": [session, anonymous]},
    ]
    reader = asyncio.StreamReader()
    reader.feed_data(b"".join(encode(m) for m in said))
    reader.feed_eof()
    feed = asyncio.create_task(asyncio.sleep(60))
    with capture_logs() as logs:
        await served._listen(reader, cast(Any, None), feed)
    shown = served.status()
    assert shown["up"] is True
    assert shown["sessions"] == [
        session | {"since": "2026-11-18T11:06:40.250Z"},
        anonymous | {"since": "2026-11-18T11:06:41.000Z"},
    ]
    assert {"event": "opcua.sessions", "users": ["scada", None]}.items() <= logs[-1].items()
    assert feed.cancelled() or feed.cancelling()  # the child is gone: its feed stops
    reader = asyncio.StreamReader()
    reader.feed_data(encode({"t": "sessions", "sessions": [anonymous]}))
    reader.feed_eof()
    await served._listen(reader, cast(Any, None), asyncio.create_task(asyncio.sleep(60)))
    assert [s["user"] for s in served.status()["sessions"]] == [None]
