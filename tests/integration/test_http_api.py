"""The HTTP API over real sockets: every endpoint, roles, outcome → status, bad bodies."""

from __future__ import annotations

import asyncio
import itertools
import time
from collections.abc import AsyncIterator
from typing import Any

import httpx
import pytest
from structlog.testing import capture_logs

from fcmaster.adapters.readlimit import VIEWER_READ_GAP_S
from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.bus.frame_log import RX, TX, FrameLog
from fcmaster.protocol.codec import DriveError, ParameterKey, ParameterValue
from tests.integration.gateway_double import FakeGateway
from tests.integration.http_harness import (
    OPERATOR,
    VIEWER,
    serving,
)

DRIVE_KEYS = {
    "name",
    "bus",
    "address",
    "protocol",
    "online",
    "control",
    "running",
    "fault",
    "warning",
    "direction",
    "at_reference",
    "output_frequency_hz",
    "output_frequency_updated_at",
    "reference_pct",
    "status_word",
    "status_bits",
    "values",
    "alarms",
    "warnings",
    "updated_at",
}


@pytest.fixture
async def gateway() -> FakeGateway:
    return FakeGateway()


@pytest.fixture
async def client(gateway: FakeGateway) -> AsyncIterator[httpx.AsyncClient]:
    async with serving(gateway) as adapter, httpx.AsyncClient(base_url=adapter.url) as c:
        yield c


# -- reads -----------------------------------------------------------------------------------


async def test_drives_lists_every_drive_state_in_configuration_order(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    gateway.reply("pump-1", running=True, hz=42.5, value=("16-14", 5.25, "A"))
    response = await client.get("/api/v1/drives", headers=VIEWER)
    assert response.status_code == 200
    drives = response.json()
    assert [d["name"] for d in drives] == ["pump-1", "fan-1"]
    assert set(drives[0]) == DRIVE_KEYS
    assert drives[0]["running"] is True
    assert drives[0]["output_frequency_hz"] == 42.5
    (current,) = drives[0]["values"].items()
    assert current[0] == "16-14"
    assert (current[1]["value"], current[1]["unit"], current[1]["name"]) == (
        5.25,
        "A",
        "Motor Current",
    )
    assert current[1]["updated_at"] == drives[0]["updated_at"]
    assert drives[0]["updated_at"].endswith("Z")
    assert drives[1]["online"] is False


async def test_drives_can_be_narrowed_to_one_line(client: httpx.AsyncClient) -> None:
    assert len((await client.get("/api/v1/drives?bus=line1", headers=VIEWER)).json()) == 2
    assert (await client.get("/api/v1/drives?bus=nope", headers=VIEWER)).json() == []


async def test_one_drive_by_name_and_404_for_an_unknown_name(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    gateway.reply("fan-1", alarms=((14, "Earth fault"),))
    response = await client.get("/api/v1/drives/fan-1", headers=VIEWER)
    assert response.status_code == 200
    assert response.json()["alarms"] == [{"code": 14, "text": "Earth fault"}]
    assert response.json()["fault"] is True
    missing = await client.get("/api/v1/drives/pump-9", headers=VIEWER)
    assert missing.status_code == 404
    assert "pump-9" in missing.json()["reason"]


async def test_buses_show_statistics_with_histograms_in_strict_json(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    stats = gateway.stats["line1"]
    stats.requests, stats.replies, stats.timeouts, stats.checksum_errors = 10, 9, 1, 2
    stats.latency.observe(0.012)
    response = await client.get("/api/v1/buses", headers=VIEWER)
    assert response.status_code == 200
    assert "Infinity" not in response.text  # json.dumps would write inf that way
    (line,) = response.json()
    assert (line["name"], line["up"], line["drives"]) == ("line1", True, ["pump-1", "fan-1"])
    assert line["stats"]["timeouts"] == 1
    assert line["stats"]["latency_s"]["buckets"][-1] == {"le": "+Inf", "count": 1}


async def test_a_drive_s_history_comes_as_columns_with_names_and_units(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    gateway.reply("pump-1", running=True, hz=42.5, value=("16-14", 5.25, "A"))
    response = await client.get("/api/v1/drives/pump-1/history", headers=VIEWER)
    assert response.status_code == 200
    history = response.json()
    assert (history["drive"], history["window_s"], len(history["t"])) == ("pump-1", 900.0, 1)
    assert [(s["key"], s["name"], s["unit"], s["data"]) for s in history["series"]] == [
        ("output_frequency_hz", "Output frequency", "Hz", [42.5]),
        ("16-14", "Motor Current", "A", [5.25]),
    ]
    assert [(e["type"], e["online"]) for e in history["events"]] == [("availability", True)]
    assert history["events"][0]["at"].endswith("Z")
    missing = await client.get("/api/v1/drives/nope/history", headers=VIEWER)
    assert missing.status_code == 404
    assert (await client.get("/api/v1/drives/pump-1/history")).status_code == 401


async def test_a_line_s_history_has_its_rates(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    stats = gateway.lines()[0].stats
    gateway.fleet.line_sampled("line1", True, {**stats, "requests": 0})
    gateway.fleet.line_sampled("line1", True, {**stats, "requests": 10})
    response = await client.get("/api/v1/buses/line1/history", headers=VIEWER)
    assert response.status_code == 200
    history = response.json()
    assert len(history["t"]) == 1
    assert history["series"]["requests_per_s"][0] > 0
    assert (await client.get("/api/v1/buses/nope/history", headers=VIEWER)).status_code == 404


async def test_a_line_s_frames_come_numbered_so_a_follower_misses_none(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    log = gateway.frames.setdefault("line1", FrameLog(gateway.clock.wall))
    log.add(TX, b"\x02\x0e\x01", 10.0)
    log.add(RX, b"\x02\x0e\x01\x33", 10.02)
    response = await client.get("/api/v1/buses/line1/frames", headers=VIEWER)
    assert response.status_code == 200
    body = response.json()
    assert (body["bus"], body["protocol"], body["next"], body["missed"]) == (
        "line1",
        "danfoss-fc",
        2,
        0,
    )
    assert body["baudrate"] == gateway.plans[0].baudrate
    assert [(f["seq"], f["dir"], f["mono"], f["data"]) for f in body["frames"]] == [
        (0, "tx", 10.0, "020e01"),
        (1, "rx", 10.02, "020e0133"),
    ]
    assert abs(body["frames"][0]["time"] - time.time()) < 60
    log.add(TX, b"\x02", 11.0)
    more = (await client.get("/api/v1/buses/line1/frames?since=2", headers=VIEWER)).json()
    assert [f["seq"] for f in more["frames"]] == [2]
    assert (await client.get("/api/v1/buses/line1/frames")).status_code == 401
    assert (await client.get("/api/v1/buses/nope/frames", headers=VIEWER)).status_code == 404
    bad = await client.get("/api/v1/buses/line1/frames?since=-1", headers=VIEWER)
    assert bad.status_code == 422


async def test_whoami_names_the_token_and_its_role(client: httpx.AsyncClient) -> None:
    response = await client.get("/api/v1/whoami", headers=OPERATOR)
    assert response.json() == {"name": "ops", "role": "operator"}
    response = await client.get("/api/v1/whoami", headers=VIEWER)
    assert response.json() == {"name": "scada", "role": "viewer"}


# -- outcomes --------------------------------------------------------------------------------

OUTCOMES = [
    (CommandResult(outcome=Outcome.DONE), 200),
    (
        CommandResult(
            outcome=Outcome.REFUSED, reason="drive refused", error=DriveError(3, "illegal value")
        ),
        409,
    ),
    (CommandResult(outcome=Outcome.NOT_ALLOWED, reason="limit of 50 Hz"), 403),
    (CommandResult(outcome=Outcome.INVALID, reason="no such parameter"), 422),
    (CommandResult(outcome=Outcome.TIMEOUT, reason="no answer after 2 attempts"), 504),
    (CommandResult(outcome=Outcome.CANCELLED, reason="line1 is down"), 503),
]


@pytest.mark.parametrize(("result", "status"), OUTCOMES, ids=[o.outcome for o, _ in OUTCOMES])
async def test_each_outcome_has_its_http_status_and_the_result_as_body(
    gateway: FakeGateway, client: httpx.AsyncClient, result: CommandResult, status: int
) -> None:
    gateway.respond = lambda _drive, _command: result
    response = await client.post(
        "/api/v1/drives/pump-1/commands", json={"action": "reset"}, headers=OPERATOR
    )
    assert response.status_code == status
    assert response.json() == result.to_json()


async def test_a_command_for_an_unknown_drive_is_404_and_goes_nowhere(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    response = await client.post(
        "/api/v1/drives/nope/commands", json={"action": "stop"}, headers=OPERATOR
    )
    assert response.status_code == 404
    assert gateway.executed == []


# -- bodies ----------------------------------------------------------------------------------

MALFORMED: list[tuple[str, bytes, str]] = [
    ("not-json", b"start!", "JSON"),
    ("not-an-object", b"[1, 2]", "body"),
    ("no-action", b"{}", "action"),
    ("unknown-action", b'{"action": "launch"}', "launch"),
    ("number-as-text", b'{"action": "start", "frequency_hz": "30"}', "frequency_hz"),
    ("bool-as-number", b'{"action": "start", "reference_pct": true}', "reference_pct"),
    ("nan", b'{"action": "start", "frequency_hz": NaN}', "NaN is not a JSON number"),
    ("infinity", b'{"action": "set_reference", "frequency_hz": Infinity}', "Infinity is not"),
    ("unknown-key", b'{"action": "stop", "frequency_hz": 10}', "frequency_hz"),
    (
        "both-references",
        b'{"action": "start", "frequency_hz": 10, "reference_pct": 20}',
        "not both",
    ),
    ("reference-missing", b'{"action": "set_reference"}', "set_reference needs"),
    ("negative-index", b'{"action": "read", "parameter": "16-13", "index": -1}', "index"),
    ("write-without-value", b'{"action": "write", "parameter": "3-41"}', "value"),
    ("duplicated-action", b'{"action": "stop", "action": "start"}', "duplicated key 'action'"),
    ("negative-frequency", b'{"action": "start", "frequency_hz": -40}', "magnitude (≥ 0)"),
    ("negative-reference", b'{"action": "set_reference", "reference_pct": -1}', "magnitude"),
    ("huge-value", b'{"action": "write", "parameter": "3-41", "value": 1e308}', "beyond"),
    ("overflowing-value", b'{"action": "write", "parameter": "3-41", "value": 1e400}', "beyond"),
]


@pytest.mark.parametrize(
    ("body", "words"), [(b, w) for _, b, w in MALFORMED], ids=[i for i, _, _ in MALFORMED]
)
async def test_malformed_commands_are_422_naming_the_problem(
    gateway: FakeGateway, client: httpx.AsyncClient, body: bytes, words: str
) -> None:
    with capture_logs() as logs:
        response = await client.post(
            "/api/v1/drives/pump-1/commands",
            content=body,
            headers={**OPERATOR, "Content-Type": "application/json"},
        )
    assert response.status_code == 422
    answer = response.json()
    assert answer["outcome"] == "invalid"
    assert words in answer["reason"]
    assert gateway.executed == []
    (refused,) = [e for e in logs if e["event"] == "http.command_refused"]
    assert (refused["actor"], refused["outcome"]) == ("ops", "invalid")


async def test_an_oversized_body_is_413_before_it_is_read(client: httpx.AsyncClient) -> None:
    response = await client.post(
        "/api/v1/drives/pump-1/commands",
        content=b'{"action": "stop", "id": "' + b"x" * 70_000 + b'"}',
        headers={**OPERATOR, "Content-Type": "application/json"},
    )
    assert response.status_code == 413


async def test_an_oversized_chunked_body_is_413_too(client: httpx.AsyncClient) -> None:
    async def chunks() -> AsyncIterator[bytes]:
        yield b'{"action": "stop", "id": "'
        for _ in range(100):
            yield b"x" * 1000
        yield b'"}'

    response = await client.post(
        "/api/v1/drives/pump-1/commands",
        content=chunks(),
        headers={**OPERATOR, "Content-Type": "application/json"},
    )
    assert response.status_code == 413


async def test_a_reference_beyond_the_limit_is_refused_with_the_limit_named(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    with capture_logs() as logs:
        response = await client.post(
            "/api/v1/drives/pump-1/commands",
            json={"action": "set_reference", "frequency_hz": 50.0000001},
            headers=OPERATOR,
        )
    assert response.status_code == 403
    reason = "50.0000001 Hz is beyond pump-1's configured limit of 50 Hz"
    assert response.json() == {"outcome": "not_allowed", "reason": reason}
    assert gateway.executed == []  # refused, never clamped on the way
    (refused,) = [e for e in logs if e["event"] == "http.command_refused"]
    assert (refused["actor"], refused["outcome"]) == ("ops", "not_allowed")


async def test_a_parameter_write_of_a_huge_number_is_invalid_not_an_error(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    response = await client.put(
        "/api/v1/drives/pump-1/parameters/3-41",
        content=b'{"value": 1e308}',
        headers={**OPERATOR, "Content-Type": "application/json"},
    )
    assert response.status_code == 422
    assert response.json()["outcome"] == "invalid"
    assert "'value' is beyond" in response.json()["reason"]
    duplicated = await client.put(
        "/api/v1/drives/pump-1/parameters/3-41",
        content=b'{"value": 1, "value": 2}',
        headers={**OPERATOR, "Content-Type": "application/json"},
    )
    assert duplicated.status_code == 422
    assert "duplicated key 'value'" in duplicated.json()["reason"]
    assert gateway.executed == []


# -- parameters ------------------------------------------------------------------------------


async def test_a_parameter_read_answers_value_unit_and_raw(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    value = ParameterValue(
        parameter=ParameterKey("15-30", 1530), index=2, raw=1234, value=12.34, unit="h"
    )
    gateway.respond = lambda _d, _c: CommandResult(outcome=Outcome.DONE, value=value)
    response = await client.get("/api/v1/drives/fan-1/parameters/15-30?index=2", headers=VIEWER)
    assert response.status_code == 200
    assert response.json() == {
        "outcome": "done",
        "reason": "",
        "value": 12.34,
        "unit": "h",
        "raw": 1234,
        "parameter": "15-30",
        "index": 2,
    }
    ((drive, command),) = gateway.executed
    assert (drive, command.action, command.parameter, command.index, command.actor) == (
        "fan-1",
        Action.READ,
        "15-30",
        2,
        "scada",
    )


async def test_a_parameter_write_needs_an_operator_and_carries_value_and_persist(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    response = await client.put(
        "/api/v1/drives/pump-1/parameters/3-41",
        json={"value": 5.5, "persist": True},
        headers=OPERATOR,
    )
    assert response.status_code == 200
    assert response.json()["parameter"] == "3-41"
    ((_, command),) = gateway.executed
    assert (command.action, command.value, command.persist) == (Action.WRITE, 5.5, True)
    bad = await client.put(
        "/api/v1/drives/pump-1/parameters/3-41", json={"value": "5"}, headers=OPERATOR
    )
    assert bad.status_code == 422


# -- metrics, dashboard, OpenAPI -------------------------------------------------------------


async def test_metrics_are_prometheus_text_from_the_state(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    gateway.reply("pump-1", running=True, hz=42.5, value=("16-14", 5.25, "A"))
    response = await client.get("/metrics", headers=VIEWER)
    assert response.status_code == 200
    assert response.headers["content-type"] == "text/plain; version=0.0.4; charset=utf-8"
    text = response.text
    assert 'fcmaster_drive_output_frequency_hz{bus="line1",drive="pump-1"} 42.5' in text
    assert 'fcmaster_drive_value{bus="line1",drive="pump-1",param="16-14",unit="A"} 5.25' in text
    assert 'fcmaster_bus_requests_total{bus="line1"} 0' in text
    assert gateway.executed == []  # a scrape never asks a line


async def test_metrics_can_be_switched_off(gateway: FakeGateway) -> None:
    async with (
        serving(gateway, metrics_enabled=False) as adapter,
        httpx.AsyncClient(base_url=adapter.url) as client,
    ):
        assert (await client.get("/metrics", headers=VIEWER)).status_code == 404


async def test_the_dashboard_and_its_files_are_served_without_a_token(
    client: httpx.AsyncClient,
) -> None:
    page = await client.get("/")
    assert page.status_code == 200
    assert page.headers["content-type"].startswith("text/html")
    assert "script-src 'self'" in page.headers["content-security-policy"]
    assert "/static/dashboard.js" in page.text
    for name, kind in (("dashboard.js", "javascript"), ("dashboard.css", "text/css")):
        asset = await client.get(f"/static/{name}")
        assert asset.status_code == 200
        assert kind in asset.headers["content-type"]
    assert page.headers["x-content-type-options"] == "nosniff"


async def test_the_openapi_document_lists_every_endpoint(client: httpx.AsyncClient) -> None:
    document: dict[str, Any] = (await client.get("/api/v1/openapi.json")).json()
    assert set(document["paths"]) >= {
        "/api/v1/drives",
        "/api/v1/drives/{name}",
        "/api/v1/drives/{name}/commands",
        "/api/v1/drives/{name}/parameters/{param}",
        "/api/v1/buses",
        "/metrics",
    }
    assert "| `timeout` | 504 |" in document["info"]["description"]
    body = document["paths"]["/api/v1/drives/{name}/commands"]["post"]["requestBody"]
    schema = body["content"]["application/json"]["schema"]
    assert schema["discriminator"]["propertyName"] == "action"


async def test_viewer_reads_are_spaced_out_per_line_and_operator_reads_are_not(
    gateway: FakeGateway, client: httpx.AsyncClient
) -> None:
    started: list[tuple[str, float]] = []

    def record(_drive: str, command: Command) -> CommandResult:
        started.append((command.actor, time.monotonic()))
        return CommandResult(outcome=Outcome.DONE)

    gateway.respond = record
    path = "/api/v1/drives/pump-1/parameters/16-13"
    viewers = [client.get(path, headers=VIEWER) for _ in range(4)]
    answers = await asyncio.gather(*viewers, client.get(path, headers=OPERATOR))
    assert [a.status_code for a in answers] == [200] * 5
    assert started[0][0] in ("scada", "ops")
    viewer_times = [t for actor, t in started if actor == "scada"]
    gaps = [b - a for a, b in itertools.pairwise(viewer_times)]
    assert len(gaps) == 3
    assert min(gaps) >= VIEWER_READ_GAP_S * 0.99
    (operator_at,) = [t for actor, t in started if actor == "ops"]
    assert operator_at < viewer_times[1]  # it did not wait behind the viewers
