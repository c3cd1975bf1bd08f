"""`fcmaster run` against a client that opens a None secure channel, with asyncua's low-level calls.

asyncua's server lets a None channel open whatever the endpoints offered. Where
``opcua.security`` has no None, the channel serves discovery (GetEndpoints) and nothing else:
its CreateSession is refused, a Stop sent over it never reaches the line and no command is
audited. Where None is offered (only allowed without commands), a None session works.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
import pytest
from asyncua import Client, ua

from tests.integration.daemon_harness import by_name, child, get_json, until
from tests.integration.ports import free_port

OPERATOR = "operator-token-0123456789abcdef"
CONFIG = """
buses:
  - name: line1
    port: {port}
    protocol: danfoss-fc
    drives:
      - {{name: pump-1, address: 1, control: bus}}
http:
  listen: 127.0.0.1:{http}
  anonymous: viewer
  tokens:
    - {{name: ops, role: operator, token: {operator}}}
opcua:
  listen: 127.0.0.1:{opcua}
  pki: pki
  security: {security}
  commands: {commands}
on_shutdown: hold
logging: {{level: info, format: json}}
"""
RUNNING = "ns=2;s=Drives/pump-1/Running"


def _session(url: str) -> ua.CreateSessionParameters:
    description = ua.ApplicationDescription(
        ApplicationUri="urn:none-channel",
        ApplicationName=ua.LocalizedText("none-channel"),
        ApplicationType=ua.ApplicationType.Client,
    )
    return ua.CreateSessionParameters(
        ClientNonce=b"x" * 32, ClientDescription=description, EndpointUrl=url,
        SessionName="none-channel", RequestedSessionTimeout=60000,
    )  # fmt: skip


async def _over_none(url: str) -> dict[str, Any]:
    """Discover, then create and activate an operator's session and start pump-1 over None."""
    seen: dict[str, Any] = {}
    client = Client(url, timeout=10)
    await client.connect_socket()
    try:
        await client.send_hello()
        await client.open_secure_channel()
        endpoints = await client.uaclient.get_endpoints(ua.GetEndpointsParameters(EndpointUrl=url))
        seen["endpoints"] = sorted(e.SecurityPolicyUri.rpartition("#")[2] for e in endpoints)
        session = _session(url)
        try:
            await client.uaclient.create_session(session)
        except ua.UaStatusCodeError as exc:
            seen["create"] = type(exc).__name__
            return seen
        seen["create"] = "Good"
        token = ua.UserNameIdentityToken(
            UserName="ops", Password=OPERATOR.encode(), PolicyId="username"
        )
        await client.uaclient.activate_session(ua.ActivateSessionParameters(
            LocaleIds=["en"], UserIdentityToken=token, UserTokenSignature=ua.SignatureData(),
            ClientSignature=ua.SignatureData(),
        ))  # fmt: skip
        seen["activate"] = "Good"
        value = await client.get_node(RUNNING).read_data_value()
        status = value.StatusCode or ua.StatusCode()
        seen["running"] = (status.name, value.Value.Value if value.Value else None)
        return seen
    finally:
        client.uaclient.disconnect_socket()


@pytest.mark.parametrize(
    ("security", "commands"),
    [
        pytest.param('["Basic256Sha256:SignAndEncrypt"]', "true", id="none-not-offered"),
        pytest.param('[None, "Basic256Sha256:SignAndEncrypt"]', "false", id="none-offered"),
    ],
)
async def test_a_none_channel_carries_sessions_only_where_none_is_offered(
    tmp_path: Path, security: str, commands: str
) -> None:
    port, http, opcua = tmp_path / "ttyFC", free_port(), free_port()
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(port=port, http=http, opcua=opcua, operator=OPERATOR,
                                    security=security, commands=commands))  # fmt: skip
    offered = "None" in security
    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        assert (await sim.readline()).split()[0] == "line1"
        async with (
            child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
            httpx.AsyncClient(base_url=f"http://127.0.0.1:{http}", timeout=15) as api,
        ):

            async def online() -> bool | None:
                return by_name(await get_json(api, "/api/v1/drives"))["pump-1"]["online"] or None

            await until(online, "pump-1 online", alive=daemon, timeout_s=60)

            async def listening() -> bool | None:
                return (await get_json(api, "/api/v1/status"))["opcua"]["up"] or None

            await until(listening, "the OPC UA server up", alive=daemon, timeout_s=60)
            seen = await _over_none(f"opc.tcp://127.0.0.1:{opcua}/")
            assert ("None" in seen["endpoints"]) is offered  # discovery works either way
            if offered:
                assert seen["create"] == "Good", seen
                assert seen["activate"] == "Good", seen
                assert seen["running"] == ("Good", False), seen
            else:
                assert seen["create"] == "BadSecurityPolicyRejected", seen
            state = by_name(await get_json(api, "/api/v1/drives"))["pump-1"]
            assert state["running"] is False
            code, _ = await daemon.stop()
            assert code == 0, daemon.tail()
        events = daemon.log_events()
        refused = [e for e in events if e["event"] == "opcua.session_refused"]
        assert bool(refused) is not offered
        assert all(e["security"] == "None" for e in refused)
        commands_seen = [e for e in events if e["event"].startswith("command.")]
        assert [e for e in commands_seen if str(e.get("actor", "")).startswith("opcua:")] == []
