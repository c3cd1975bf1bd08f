"""The journal of a real daemon on a pty line: it outlives the process, and a disk that
cannot take it costs one logged error, never the line.
"""

from __future__ import annotations

import json
import signal
from pathlib import Path
from typing import Any

import httpx

from tests.integration.daemon_harness import Child, by_name, child, get_json, until
from tests.integration.ports import free_port

OPERATOR = "operator-token-0123456789abcdef"

CONFIG = """
buses:
  - name: north
    port: {north}
    baudrate: 38400
    drives:
      - {{name: pump-1, address: 1, control: bus}}
      - {{name: pump-2, address: 2}}
http:
  listen: 127.0.0.1:{port}
  anonymous: viewer
  tokens:
    - {{name: ops, role: operator, token: {operator}}}
journal: {{path: {journal}}}
"""


def _plant(tmp_path: Path, journal: str) -> tuple[Path, int]:
    port = free_port()
    config = tmp_path / "plant.yaml"
    config.write_text(
        CONFIG.format(north=tmp_path / "ttyNORTH", port=port, operator=OPERATOR, journal=journal)
    )
    return config, port


def _client(port: int) -> httpx.AsyncClient:
    headers = {"Authorization": f"Bearer {OPERATOR}"}
    return httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}", headers=headers, timeout=10)


async def _online(client: httpx.AsyncClient, daemon: Child) -> None:
    async def online() -> bool:
        return all(d["online"] for d in await get_json(client, "/api/v1/drives"))

    await until(online, "drives online", alive=daemon)


async def _events_cli(config: Path, *args: str, log: Path) -> list[dict[str, Any]]:
    async with child("events", "--config", str(config), "--json", *args, log=log) as cli:
        assert cli.process.stdout is not None
        out = await cli.process.stdout.read()
        assert await cli.process.wait() == 0, cli.tail()
    records: list[dict[str, Any]] = json.loads(out)
    return records


async def test_the_last_ended_command_survives_sigkill_and_shows_after_a_restart(
    tmp_path: Path,
) -> None:
    config, port = _plant(tmp_path, str(tmp_path / "state" / "journal.db"))
    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        await sim.readline()
        async with (
            child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
            _client(port) as client,
        ):
            await _online(client, daemon)
            command = {"action": "set_reference", "frequency_hz": 12.5}
            answer = await client.post("/api/v1/drives/pump-1/commands", json=command)
            assert answer.json()["outcome"] == "done", answer.text

            async def journaled() -> list[dict[str, Any]]:
                records = await get_json(client, "/api/v1/events?kind=command&drive=pump-1")
                return [r for r in records if r["action"] == "set_reference"]

            (seen,) = await until(journaled, "the command in the journal", alive=daemon)
            daemon.process.send_signal(signal.SIGKILL)  # no shutdown, no flush
            await daemon.process.wait()

        # Read by another process while no daemon runs: the command is the last one.
        commands = await _events_cli(config, "--kind", "command", log=tmp_path / "cli.log")
        last = commands[-1]
        assert {k: last[k] for k in ("seq", "bus", "drive", "actor", "action", "outcome")} == {
            "seq": seen["seq"], "bus": "north", "drive": "pump-1", "actor": "ops",
            "action": "set_reference", "outcome": "done",
        }  # fmt: skip
        assert last["reference_pct"] == 25.0

        async with (
            child("run", "--config", str(config), log=tmp_path / "run-2.log") as daemon,
            _client(port) as client,
        ):
            await _online(client, daemon)
            records = await get_json(client, "/api/v1/events")
            kinds = [r["kind"] for r in records]
            # Before the restart: the first start, the command; then the second start.
            assert kinds.count("start") == 2
            assert kinds.index("command") < len(kinds) - 1 - kinds[::-1].index("start")
            assert [r["seq"] for r in records] == sorted(r["seq"] for r in records)
            texts = await _events_cli(config, log=tmp_path / "cli-2.log")
            assert texts[-1]["seq"] >= records[-1]["seq"]


async def test_a_journal_on_a_full_disk_is_one_logged_error_and_the_line_keeps_polling(
    tmp_path: Path,
) -> None:
    # /dev/full: every write the kernel is asked for fails with "no space left on device".
    config, port = _plant(tmp_path, "/dev/full")
    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        await sim.readline()
        async with (
            child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
            _client(port) as client,
        ):
            await _online(client, daemon)
            requests = by_name(await get_json(client, "/api/v1/buses"))["north"]["stats"][
                "requests"
            ]
            for frequency in (10, 20, 30):  # commands end as ever, with nowhere to keep them
                command = {"action": "set_reference", "frequency_hz": frequency}
                answer = await client.post("/api/v1/drives/pump-1/commands", json=command)
                assert answer.json()["outcome"] == "done", answer.text

            async def polled_on() -> bool:
                buses = by_name(await get_json(client, "/api/v1/buses"))
                return bool(buses["north"]["stats"]["requests"] >= requests + 200)

            await until(polled_on, "200 more polls", alive=daemon)
            assert await get_json(client, "/api/v1/events") == []
            for query, named in (("since=yesterday", "since"), ("kind=nope", "kind")):
                refused = await client.get(f"/api/v1/events?{query}")
                assert refused.status_code == 422
                assert refused.json()["reason"].startswith(named), refused.text
            code, _ = await daemon.stop(signal.SIGTERM)
    assert code == 0, daemon.tail()
    failed = [e for e in daemon.log_events() if e["event"] == "store.write_failed"]
    assert len(failed) == 1, failed
    assert failed[0]["level"] == "error"
    assert "full" in failed[0]["error"]
