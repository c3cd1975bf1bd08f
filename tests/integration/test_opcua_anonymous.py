"""`fcmaster run` with anonymous OPC UA sessions switched on, against `fcmaster sim` on a pty.

An anonymous node-opcua session may read, but its method call and its write are refused
(BadUserAccessDenied), logged with actor ``opcua:anonymous``, and nothing reaches the line.
While it and an operator's session are open, ``GET /api/v1/status`` lists both, and the
dashboard's gateway view in Chromium shows them.
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import httpx
from playwright.async_api import expect

from fcmaster.opcua import pki
from tests.integration.browser_harness import chromium, chromium_marks
from tests.integration.daemon_harness import by_name, child, get_json, until
from tests.integration.opcua_client import run_plan
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
  anonymous: true
  commands: true
on_shutdown: hold
logging: {{level: info, format: json}}
"""
RUNNING = "ns=2;s=Drives/pump-1/Running"
START = "ns=2;s=Drives/pump-1/Start"


async def test_an_anonymous_session_reads_but_never_commands(tmp_path: Path) -> None:
    browser_marks = chromium_marks()  # under CI a missing Chromium fails here, before all else
    port, http, opcua = tmp_path / "ttyFC", free_port(), free_port()
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(port=port, http=http, opcua=opcua, operator=OPERATOR))
    url = f"opc.tcp://127.0.0.1:{opcua}/"
    client_pki = tmp_path / "client-pki"

    def plan(user: str | None, *steps: dict[str, Any]) -> dict[str, Any]:
        password = OPERATOR if user else None
        return {"url": url, "pki": str(client_pki), "user": user, "password": password,
                "steps": list(steps)}  # fmt: skip

    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        assert (await sim.readline()).split()[0] == "line1"
        async with (
            child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
            httpx.AsyncClient(base_url=f"http://127.0.0.1:{http}", timeout=15) as api,
        ):

            async def online() -> bool | None:
                return by_name(await get_json(api, "/api/v1/drives"))["pump-1"]["online"] or None

            await until(online, "pump-1 online", alive=daemon, timeout_s=60)

            async def refused() -> dict[str, Any] | None:
                found = await run_plan(
                    plan(None, {"op": "read", "nodes": [RUNNING]}), tmp_path / "c"
                )
                return found if "BadCertificateUntrusted" in found.get("error", "") else None

            await until(refused, "the client's certificate refused", alive=daemon, timeout_s=60)
            (rejected,) = pki.certificates(tmp_path / "pki")["rejected"]
            pki.trust(tmp_path / "pki", rejected["thumbprint"])

            released = tmp_path / "release"
            hold = {"op": "hold", "file": str(released), "timeout_ms": 90000}
            anonymous = asyncio.create_task(run_plan(
                plan(None,
                     {"op": "read", "nodes": [RUNNING]},
                     {"op": "call", "object": "ns=2;s=Drives/pump-1", "method": START},
                     {"op": "write", "node": RUNNING, "value": True},
                     hold),
                tmp_path / "anonymous",
            ))  # fmt: skip
            operator = asyncio.create_task(run_plan(plan("ops", hold), tmp_path / "operator"))

            async def both() -> list[dict[str, Any]] | None:
                sessions: list[dict[str, Any]] = (await get_json(api, "/api/v1/status"))["opcua"][
                    "sessions"
                ]
                return sessions if len(sessions) == 2 else None

            try:
                sessions = await until(both, "two OPC UA sessions", alive=daemon, timeout_s=60)
                assert sorted(s["user"] or "" for s in sessions) == ["", "ops"]
                assert {s["security"] for s in sessions} == {"Basic256Sha256:SignAndEncrypt"}
                if not browser_marks:
                    await _gateway_view_shows(http)
            finally:
                released.touch()
            read, call, write, held = (await anonymous)["steps"]
            assert (await operator)["steps"] == [{"held": True}]
            assert held == {"held": True}
            shown = read["values"][RUNNING]
            assert (shown["status"], shown["value"]) == ("Good", False)
            # refused as a request (a service fault, as node-opcua reports it), before any method
            assert "BadUserAccessDenied" in call.get("status", call.get("error", "")), call
            assert "BadUserAccessDenied" in write.get("status", write.get("error", "")), write
            state = by_name(await get_json(api, "/api/v1/drives"))["pump-1"]
            assert state["running"] is False  # nothing reached the drive
            code, _ = await daemon.stop()
            assert code == 0, daemon.tail()
        events = daemon.log_events()
        refusals = {
            (e["actor"], e["request"]) for e in events if e["event"] == "opcua.request_refused"
        }
        assert {("opcua:anonymous", "CallRequest"), ("opcua:anonymous", "WriteRequest")} <= refusals
        commands = [e for e in events if e["event"] == "command.completed"]
        assert [e for e in commands if e["actor"].startswith("opcua:")] == []


async def _gateway_view_shows(http: int) -> None:
    """The dashboard's gateway view lists both sessions, as a person reads them."""
    async with chromium() as browser:
        page = await browser.new_page(viewport={"width": 1280, "height": 900})
        problems: list[str] = []
        page.on("pageerror", lambda error: problems.append(str(error)))
        await page.goto(f"http://127.0.0.1:{http}/")
        card = page.get_by_test_id("opcua")
        await expect(card).to_be_visible(timeout=20000)
        await expect(card).to_contain_text("up")
        await expect(card).to_contain_text("2 sessions")
        rows = page.get_by_test_id("opcua-session")
        await expect(rows).to_have_count(2)
        for user in ("ops", "anonymous"):
            row = rows.filter(has_text=user)
            await expect(row).to_contain_text("fcmaster-test-client")
            await expect(row).to_contain_text("Basic256Sha256:SignAndEncrypt")
            await expect(row).to_contain_text("127.0.0.1:")
        assert problems == []
