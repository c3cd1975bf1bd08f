"""The HTTP API's security over real sockets: tokens and roles, anonymous loopback reads,
read-only without tokens, CORS, the demo's operator token, and the listener."""

from __future__ import annotations

from collections.abc import AsyncIterator

import httpx
import pytest
from structlog.testing import capture_logs

from fcmaster.adapters.http import HttpAdapter
from fcmaster.bus.commands import Action, Command
from fcmaster.errors import ConfigError
from tests.integration.gateway_double import FakeGateway
from tests.integration.http_harness import (
    OPERATOR,
    VIEWER,
    http_settings,
    serving,
)


@pytest.fixture
async def gateway() -> FakeGateway:
    return FakeGateway()


@pytest.fixture
async def client(gateway: FakeGateway) -> AsyncIterator[httpx.AsyncClient]:
    async with serving(gateway) as adapter, httpx.AsyncClient(base_url=adapter.url) as c:
        yield c


# -- authentication --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "headers",
    [
        pytest.param({}, id="no-token"),
        pytest.param({"Authorization": "Bearer not-a-known-token"}, id="unknown-token"),
        pytest.param({"Authorization": "Basic b3BzOnNlY3JldA=="}, id="basic-auth"),
        pytest.param({"Authorization": "Bearer"}, id="empty-bearer"),
    ],
)
async def test_reads_without_a_valid_token_are_401_with_a_bearer_challenge(
    client: httpx.AsyncClient, headers: dict[str, str]
) -> None:
    for path in ("/api/v1/drives", "/api/v1/drives/pump-1", "/api/v1/buses", "/metrics"):
        response = await client.get(path, headers=headers)
        assert response.status_code == 401, path
        assert response.headers["www-authenticate"] == "Bearer"
        assert response.json()["reason"]


async def test_a_viewer_cannot_command_and_the_refusal_is_logged_with_its_name(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    with capture_logs() as logs:
        response = await client.post(
            "/api/v1/drives/pump-1/commands", json={"action": "start"}, headers=VIEWER
        )
        write = await client.put(
            "/api/v1/drives/pump-1/parameters/3-41", json={"value": 5}, headers=VIEWER
        )
    assert response.status_code == 403
    assert write.status_code == 403
    assert "operator" in response.json()["reason"]
    assert gateway.executed == []
    refused = [e for e in logs if e["event"] == "http.command_refused"]
    assert refused[0] == {
        "event": "http.command_refused",
        "log_level": "info",
        "actor": "scada",
        "drive": "pump-1",
        "command": "start",
        "outcome": "forbidden",
        "reason": response.json()["reason"],
    }


async def test_an_operator_command_reaches_the_drive_with_the_token_name_as_actor(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    response = await client.post(
        "/api/v1/drives/pump-1/commands",
        json={"action": "start", "frequency_hz": 30, "id": "c-1"},
        headers=OPERATOR,
    )
    assert response.status_code == 200
    assert response.json() == {"outcome": "done", "reason": "", "id": "c-1"}
    ((drive, command),) = gateway.executed
    assert drive == "pump-1"
    assert command == Command(action=Action.START, reference_pct=60.0, actor="ops")


# -- anonymous reads, no tokens, CORS --------------------------------------------------------


async def test_anonymous_viewer_reads_on_loopback_but_cannot_command(
    gateway: FakeGateway,
) -> None:
    async with (
        serving(gateway, http_settings(anonymous="viewer")) as adapter,
        httpx.AsyncClient(base_url=adapter.url) as client,
    ):
        assert (await client.get("/api/v1/drives")).status_code == 200
        assert (await client.get("/api/v1/whoami")).json() == {
            "name": "anonymous",
            "role": "viewer",
        }
        command = await client.post("/api/v1/drives/pump-1/commands", json={"action": "start"})
        assert command.status_code == 401
        # A page that re-binds its own DNS name to 127.0.0.1 still names that host.
        rebound = await client.get("/api/v1/drives", headers={"Host": "evil.example:8080"})
        assert rebound.status_code == 401
    assert gateway.executed == []


async def test_without_tokens_the_api_is_read_only(gateway: FakeGateway) -> None:
    async with (
        serving(gateway, http_settings(tokens=())) as adapter,
        httpx.AsyncClient(base_url=adapter.url) as client,
    ):
        assert (await client.get("/api/v1/drives")).status_code == 200
        response = await client.post("/api/v1/drives/pump-1/commands", json={"action": "stop"})
        assert response.status_code == 401
    assert gateway.executed == []


async def test_without_tokens_only_loopback_may_be_listened_on(gateway: FakeGateway) -> None:
    adapter = HttpAdapter(http_settings(tokens=(), listen="0.0.0.0:0"), gateway)
    with pytest.raises(ConfigError) as caught:
        await adapter.__aenter__()
    assert caught.value.problems[0][0] == "http.listen"


async def test_cors_is_off_by_default_and_on_for_configured_origins(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    preflight = {
        "Origin": "http://scada.example",
        "Access-Control-Request-Method": "POST",
        "Access-Control-Request-Headers": "authorization,content-type",
    }
    response = await client.options("/api/v1/drives/pump-1/commands", headers=preflight)
    assert "access-control-allow-origin" not in response.headers
    settings = http_settings(cors_origins=("http://scada.example",))
    async with serving(gateway, settings) as adapter, httpx.AsyncClient(base_url=adapter.url) as c:
        response = await c.options("/api/v1/drives/pump-1/commands", headers=preflight)
        assert response.headers["access-control-allow-origin"] == "http://scada.example"


async def test_the_demo_makes_up_an_operator_token_and_prints_it(
    gateway: FakeGateway, capsys: pytest.CaptureFixture[str]
) -> None:
    async with (
        serving(gateway, http_settings(tokens=(), anonymous="viewer"), demo=True) as adapter,
        httpx.AsyncClient(base_url=adapter.url) as client,
    ):
        token = adapter.operator_token
        assert token is not None
        printed = capsys.readouterr().out
        assert f"{adapter.url}/#token={token}" in printed
        assert (await client.get("/api/v1/drives")).status_code == 200  # anonymous reads
        response = await client.post(
            "/api/v1/drives/pump-1/commands",
            json={"action": "stop"},
            headers={"Authorization": f"Bearer {token}"},
        )
        assert response.status_code == 200
    assert gateway.executed[0][1].actor == "demo-operator"


async def test_a_port_in_use_is_a_config_error_naming_http_listen(gateway: FakeGateway) -> None:
    async with serving(gateway) as first:
        taken = first.url.removeprefix("http://")
        second = HttpAdapter(http_settings(listen=taken), gateway)
        with pytest.raises(ConfigError) as caught:
            await second.__aenter__()
        assert caught.value.problems[0][0] == "http.listen"
        with pytest.raises(RuntimeError, match="already running"):
            await first.__aenter__()
