"""`fcmaster run` with an OPC UA server, against `fcmaster sim` on a pty, read by node-opcua.

One daemon serves the whole story, in the order an engineer meets it: only the secure
endpoints are offered; the client's certificate is refused and filed, then trusted with
`fcmaster opcua trust`; a viewer browses and reads every quality state the simulator drives
(a drive never heard, a live one, one that fell silent), cannot call or write; an operator
subscribes, starts a drive by its method and sees the change; the line goes down (the
simulator stops) and the values turn Uncertain with their last value. On the way the server
process is killed: the daemon starts another, which shows the same, and the line never
noticed.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
from pathlib import Path
from typing import Any

import httpx

from tests.integration.daemon_harness import Child, by_name, child, get_json, until
from tests.integration.opcua_client import run_plan
from tests.integration.ports import free_port

VIEWER = "viewer-token-0123456789abcdef"
OPERATOR = "operator-token-0123456789abcdef"
CONFIG = """
buses:
  - name: line1
    port: {port}
    protocol: danfoss-fc
    drives:
      - {{name: pump-1, address: 1, control: bus}}
      - {{name: pump-2, address: 2}}
      - {{name: pump-3, address: 3}}
    simulation:
      drives:
        2: {{faults: "silent_at=0-100000"}}
        3: {{faults: "silent_at=25-100000"}}
http:
  listen: 127.0.0.1:{http}
  anonymous: viewer
  tokens:
    - {{name: scada, role: viewer, token: {viewer}}}
    - {{name: ops, role: operator, token: {operator}}}
opcua:
  listen: 127.0.0.1:{opcua}
  pki: pki
  commands: true
on_shutdown: hold
logging: {{level: info, format: json}}
"""
STATUS = "ns=2;s=Drives/{}/{}"


def node(drive: str, variable: str) -> str:
    return STATUS.format(drive, variable)


async def _fcmaster(*args: str, log: Path) -> tuple[int, str]:
    async with child(*args, log=log) as tool:
        assert tool.process.stdout is not None
        out = await tool.process.stdout.read()
        return await tool.process.wait(), out.decode()


async def test_scada_connects_trusts_reads_qualities_and_commands(tmp_path: Path) -> None:
    port, http, opcua = tmp_path / "ttyFC", free_port(), free_port()
    config = tmp_path / "plant.yaml"
    config.write_text(
        CONFIG.format(port=port, http=http, opcua=opcua, viewer=VIEWER, operator=OPERATOR)
    )
    url = f"opc.tcp://127.0.0.1:{opcua}/"
    client_pki = tmp_path / "client-pki"

    def plan(user: str | None, *steps: dict[str, Any]) -> dict[str, Any]:
        password = {"scada": VIEWER, "ops": OPERATOR}.get(user or "")
        return {"url": url, "pki": str(client_pki), "user": user, "password": password,
                "steps": list(steps)}  # fmt: skip

    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        assert (await sim.readline()).split()[0] == "line1"
        async with (
            child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
            httpx.AsyncClient(base_url=f"http://127.0.0.1:{http}", timeout=15) as api,
        ):

            async def endpoints() -> Any:
                found = await run_plan(plan(None, {"op": "endpoints"}), tmp_path / "c")
                return found["steps"][0]["endpoints"] if "error" not in found else None

            offered = await until(endpoints, "the OPC UA endpoints", alive=daemon)
            # Only what opcua.security lists (its default): no None endpoint, user names only.
            assert sorted((e["policy"], e["mode"]) for e in offered) == [
                ("Aes256_Sha256_RsaPss", "SignAndEncrypt"),
                ("Basic256Sha256", "SignAndEncrypt"),
            ]
            assert all(e["tokens"] == ["UserName"] for e in offered)

            await _trust_the_client(plan, tmp_path, config, daemon)
            await _viewer_reads_qualities(plan, tmp_path, api, daemon)
            await _sessions_shown(plan, tmp_path, api, daemon)
            await _operator_commands(plan, tmp_path, api, daemon)
            await _server_restarts_alone(plan, tmp_path, api, daemon)

            # The line goes down: the values keep their last reading, Uncertain.
            assert (await sim.stop())[0] == 0

            async def line_down() -> dict[str, Any] | None:
                nodes = ["ns=2;s=Lines/line1/Up", node("pump-1", "Running")]
                nodes.append(node("pump-1", "Online"))
                read = plan("scada", {"op": "read", "nodes": nodes})
                found = await run_plan(read, tmp_path / "c")
                values: dict[str, Any] = found["steps"][0]["values"]
                return values if values["ns=2;s=Lines/line1/Up"]["value"] is False else None

            values = await until(line_down, "the line shown down", alive=daemon)
            running = values[node("pump-1", "Running")]
            assert running["status"] == "UncertainNoCommunicationLastUsableValue"
            assert running["value"] is True  # the last value read: it was running
            assert values[node("pump-1", "Online")]["value"] is False
            code, _ = await daemon.stop()
            assert code == 0, daemon.tail()
        events = daemon.log_events()
        refused = {
            (e["actor"], e["request"]) for e in events if e["event"] == "opcua.request_refused"
        }
        assert ("opcua:scada", "WriteRequest") in refused  # the server process logs who tried
        audits = [e for e in events if e["event"] == "command.completed"]
        assert {(a["actor"], a["command"], a["outcome"]) for a in audits} >= {
            ("opcua:scada", "start", "not_allowed"),
            ("opcua:ops", "start", "done"),
        }


async def _trust_the_client(plan: Any, tmp_path: Path, config: Path, daemon: Child) -> None:
    refused = await run_plan(plan("ops", {"op": "browse", "node": "ns=2;s=Drives"}), tmp_path / "c")
    assert "BadCertificateUntrusted" in refused["error"], refused
    code, out = await _fcmaster("opcua", "certs", "--config", str(config), "--json",
                                log=tmp_path / "certs.log")  # fmt: skip
    assert code == 0
    listed = json.loads(out)
    assert len(listed["own"]) == 1
    assert listed["trusted"] == []
    (rejected,) = listed["rejected"]
    assert "fcmaster-test-client" in rejected["subject"]
    code, out = await _fcmaster("opcua", "trust", "--config", str(config), rejected["thumbprint"],
                                log=tmp_path / "trust.log")  # fmt: skip
    assert code == 0, out
    code, out = await _fcmaster("opcua", "certs", "--config", str(config), "--json",
                                log=tmp_path / "certs.log")  # fmt: skip
    listed = json.loads(out)
    assert [c["thumbprint"] for c in listed["trusted"]] == [rejected["thumbprint"]]
    assert listed["rejected"] == []


async def _viewer_reads_qualities(
    plan: Any, tmp_path: Path, api: httpx.AsyncClient, daemon: Child
) -> None:
    async def silenced() -> bool | None:
        drives = by_name(await get_json(api, "/api/v1/drives"))
        pump3 = drives["pump-3"]
        return (pump3["updated_at"] is not None and not pump3["online"]) or None

    await until(silenced, "pump-3 answering, then silent", alive=daemon, timeout_s=60)
    names = ("Running", "OutputFrequency", "StatusWord", "Online")
    nodes = [node(d, n) for d in ("pump-1", "pump-2", "pump-3") for n in names]
    found = await run_plan(
        plan("scada",
             {"op": "browse", "node": "ns=2;s=Drives"},
             {"op": "browse", "node": "ns=2;s=Drives/pump-1"},
             {"op": "read", "nodes": nodes},
             {"op": "call", "object": "ns=2;s=Drives/pump-1",
              "method": node("pump-1", "Start")},
             {"op": "write", "node": node("pump-1", "Running"), "value": True}),
        tmp_path / "c",
    )  # fmt: skip
    assert "error" not in found, found
    drives, pump1, read, call, write = found["steps"]
    assert sorted(drives["names"]) == ["pump-1", "pump-2", "pump-3"]
    assert {"Running", "OutputFrequency", "Values", "Start", "SetReference"} <= set(pump1["names"])
    values = read["values"]
    live = values[node("pump-1", "OutputFrequency")]
    assert live["status"] == "Good"
    assert live["value"] == 0
    assert live["source"] <= live["server"]
    never = values[node("pump-2", "Running")]
    assert never == {**never, "status": "BadWaitingForInitialData", "value": None}
    assert values[node("pump-2", "Online")] == {**values[node("pump-2", "Online")], "value": False}
    silent = values[node("pump-3", "StatusWord")]
    assert silent["status"] == "UncertainNoCommunicationLastUsableValue"
    assert isinstance(silent["value"], int)
    state = by_name(await get_json(api, "/api/v1/drives"))["pump-3"]
    assert silent["source"] == state["updated_at"]  # the reading's time, to the millisecond
    assert call["status"] == "BadUserAccessDenied"
    await _never_heard_values_wait(plan, tmp_path)
    # Nobody writes: the request itself is refused (a service fault, as node-opcua reports it)
    assert "BadUserAccessDenied" in write.get("status", write.get("error", "")), write


async def _never_heard_values_wait(plan: Any, tmp_path: Path) -> None:
    """A drive never heard shows its monitored values from the start, each waiting."""
    listed = await run_plan(
        plan("scada", *({"op": "browse", "node": node(d, "Values")} for d in ("pump-1", "pump-2"))),
        tmp_path / "c",
    )
    heard, never = (step["names"] for step in listed["steps"])
    assert "Motor Current" in never  # the manual's name, as the drive state gives it
    assert sorted(never) == sorted(heard)
    values = [node("pump-2", f"Values/{name}") for name in never]
    read = await run_plan(plan("scada", {"op": "read", "nodes": values}), tmp_path / "c")
    shown = read["steps"][0]["values"]
    assert {(v["status"], v["value"]) for v in shown.values()} == {
        ("BadWaitingForInitialData", None)
    }


async def _sessions_shown(plan: Any, tmp_path: Path, api: httpx.AsyncClient, daemon: Child) -> None:
    """A session is listed in the daemon's status, with its user, while it lasts."""
    released = tmp_path / "release"
    held = asyncio.create_task(
        run_plan(plan("scada", {"op": "hold", "file": str(released), "timeout_ms": 60000}),
                 tmp_path / "held")
    )  # fmt: skip

    async def listed() -> list[dict[str, Any]] | None:
        sessions: list[dict[str, Any]] = (await get_json(api, "/api/v1/status"))["opcua"][
            "sessions"
        ]
        return sessions or None

    try:
        (session,) = await until(listed, "the OPC UA session in the status", alive=daemon)
    finally:
        released.touch()
    status = (await get_json(api, "/api/v1/status"))["opcua"]
    listen = plan(None)["url"].removeprefix("opc.tcp://").rstrip("/")
    assert (status["listen"], status["up"], status["restarts"]) == (listen, True, 0)
    assert session["user"] == "scada"
    assert session["application"] == "fcmaster-test-client"
    assert session["security"] == "Basic256Sha256:SignAndEncrypt"
    assert session["client"].startswith("127.0.0.1:")
    assert session["since"].endswith("Z")
    assert (await held)["steps"] == [{"held": True}]

    async def gone() -> bool | None:
        return (await get_json(api, "/api/v1/status"))["opcua"]["sessions"] == [] or None

    await until(gone, "the closed session gone from the status", alive=daemon)


async def _operator_commands(
    plan: Any, tmp_path: Path, api: httpx.AsyncClient, daemon: Child
) -> None:
    running = node("pump-1", "Running")
    found = await run_plan(
        plan("ops",
             {"op": "call", "object": "ns=2;s=Drives/pump-1",
              "method": node("pump-1", "SetReference"), "args": [99]},
             {"op": "call", "object": "ns=2;s=Drives/pump-1",
              "method": node("pump-1", "Start")},
             {"op": "subscribe", "nodes": [running], "until": {"node": running, "value": True},
              "timeout_ms": 20000}),
        tmp_path / "c",
    )  # fmt: skip
    assert "error" not in found, found
    beyond, started, subscribed = found["steps"]
    assert beyond["status"] == "Good"
    assert beyond["outputs"][0] == "not_allowed"
    assert "99" in beyond["outputs"][1]
    assert started == {"status": "Good", "outputs": ["done", ""]}
    assert [c["value"] for c in subscribed["changes"] if c["node"] == running][-1] is True
    state = by_name(await get_json(api, "/api/v1/drives"))["pump-1"]
    assert state["running"] is True


async def _server_restarts_alone(
    plan: Any, tmp_path: Path, api: httpx.AsyncClient, daemon: Child
) -> None:
    def serving() -> int:
        return sum(e["event"] == "opcua.serving" for e in daemon.log_events())

    before = serving()
    (pid,) = [e["pid"] for e in daemon.log_events() if e["event"] == "opcua.server_started"]
    os.kill(pid, signal.SIGKILL)

    async def again() -> bool | None:
        return serving() > before or None

    await until(again, "another OPC UA server", alive=daemon)
    running = node("pump-1", "Running")
    found = await run_plan(plan("scada", {"op": "read", "nodes": [running]}), tmp_path / "c")
    shown = found["steps"][0]["values"][running]
    assert (shown["value"], shown["status"]) == (True, "Good")
    line = by_name(await get_json(api, "/api/v1/buses"))["line1"]
    assert line["up"] is True
    assert line["stats"]["reopens"] == 0
    status = (await get_json(api, "/api/v1/status"))["opcua"]
    assert (status["up"], status["restarts"]) == (True, 1)
    state = by_name(await get_json(api, "/api/v1/drives"))["pump-1"]
    assert (state["online"], state["running"]) == (True, True)
