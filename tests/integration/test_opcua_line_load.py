"""OPC UA clients never starve a line: 126 ramping drives on a pty, without and with clients.

`fcmaster sim` serves one line of 126 FC drives on a pseudo-terminal at 115200 baud, every
drive running on a ten-minute ramp so that each poll reads a new speed; `fcmaster run`
polls them through the real serial path and serves OPC UA. The line is watched for a
window with no client, then for one with 3 node-opcua clients each subscribed to every
variable of every drive (2,394 of them).

What a plant needs is asserted: each client gets every variable and a stream of changes,
and every drive keeps being answered while they do, as without them. The line's rate and
its slowest drive's gap in both windows are printed for the record, not judged: this
machine is shared, and ``benchmarks/opcua_load.py`` measures them.
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any, Final

import httpx

from fcmaster.opcua import pki
from tests.integration.daemon_harness import child, get_json, until
from tests.integration.opcua_client import finished, run_plan, start_plan, subscribed
from tests.integration.ports import free_port

DRIVES: Final = 126
WINDOW_S: Final = 8.0
CLIENTS: Final = 3
OPERATOR: Final = "operator-token-0123456789abcdef"
VIEWER: Final = "viewer-token-0123456789abcdef"
STATUS: Final = (
    "Online", "Running", "Fault", "Warning", "AtReference", "Direction", "StatusWord",
    "OutputFrequency", "ReferencePercent", "Alarms", "Warnings", "WatchdogVerdict",
)  # fmt: skip


def _config(port: Path, http: int, opcua: int) -> str:
    running = ", ".join(
        f"{a}: {{running_hz: {5 + a % 10}, parameters: {{'3-41': 600}}}}"
        for a in range(1, DRIVES + 1)
    )
    drives = "".join(
        f"      - {{name: d{a}, address: {a}, control: bus}}\n" for a in range(1, DRIVES + 1)
    )
    return (
        f"buses:\n  - name: line1\n    port: {port}\n    baudrate: 115200\n"
        f"    simulation: {{drives: {{{running}}}}}\n    drives:\n{drives}"
        f"http:\n  listen: 127.0.0.1:{http}\n  anonymous: viewer\n  tokens:\n"
        f"    - {{name: scada, role: viewer, token: {VIEWER}}}\n"
        f"    - {{name: ops, role: operator, token: {OPERATOR}}}\n"
        f"opcua:\n  listen: 127.0.0.1:{opcua}\n  pki: pki\n"
        "logging: {level: warning, format: json}\n"
    )


async def _line(api: httpx.AsyncClient) -> tuple[int, dict[str, int]]:
    """The line's requests so far, and each drive's good replies."""
    (bus,) = await get_json(api, "/api/v1/buses")
    stats = bus["stats"]
    return stats["requests"], {name: d["replies"] for name, d in stats["drives"].items()}


async def _window(api: httpx.AsyncClient) -> dict[str, Any]:
    requests, replies = await _line(api)
    loop = asyncio.get_running_loop()
    start = loop.time()
    await asyncio.sleep(WINDOW_S)
    requests_after, replies_after = await _line(api)
    took = loop.time() - start
    answered = {name: replies_after[name] - replies[name] for name in replies_after}
    return {"rate": (requests_after - requests) / took, "answered": answered, "took": took}


async def test_clients_subscribed_to_every_variable_leave_every_drive_answered(
    tmp_path: Path,
) -> None:
    port, http, opcua = tmp_path / "ttyFC", free_port(), free_port()
    config = tmp_path / "plant.yaml"
    config.write_text(_config(port, http, opcua))
    url = f"opc.tcp://127.0.0.1:{opcua}/"
    plan = {"url": url, "pki": str(tmp_path / "client-pki"), "user": "scada",
            "password": VIEWER}  # fmt: skip
    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        assert (await sim.readline()).split()[0] == "line1"
        async with (
            child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
            httpx.AsyncClient(base_url=f"http://127.0.0.1:{http}", timeout=60) as api,
        ):

            async def online() -> list[dict[str, Any]] | None:
                drives: list[dict[str, Any]] = await get_json(api, "/api/v1/drives")
                return drives if all(d["online"] and d["values"] for d in drives) else None

            drives = await until(online, "every drive online", alive=daemon, timeout_s=120)
            await _ramp(api, [d["name"] for d in drives])

            async def refused() -> bool | None:
                browse = {**plan, "steps": [{"op": "browse", "node": "ns=2;s=Drives"}]}
                found = await run_plan(browse, tmp_path / "c")
                return "BadCertificateUntrusted" in found.get("error", "") or None

            await until(refused, "the client's certificate refused", alive=daemon, timeout_s=60)
            (rejected,) = pki.certificates(tmp_path / "pki")["rejected"]
            pki.trust(tmp_path / "pki", rejected["thumbprint"])

            browse = {**plan, "steps": [{"op": "browse", "node": "ns=2;s=Drives/d1/Values"}]}
            (listed,) = (await run_plan(browse, tmp_path / "c"))["steps"]
            names = sorted(listed["names"])  # the monitor list: the same for every drive here

            async def all_read() -> bool | None:
                drives = await get_json(api, "/api/v1/drives")
                return all(len(d["values"]) == len(names) for d in drives) or None

            await until(all_read, "every monitored value read", alive=daemon, timeout_s=60)
            nodes = [
                f"ns=2;s=Drives/{d['name']}/{variable}"
                for d in drives
                for variable in (*STATUS, *(f"Values/{name}" for name in names))
            ]
            # Every variable of the first, a middle and the last drive is there, read from it
            # (all 2,394 in one read would outgrow what the client prints).
            sample = [n for n in nodes if n.split("/")[1] in {"d1", "d63", f"d{DRIVES}"}]
            read = await run_plan(
                {**plan, "steps": [{"op": "read", "nodes": sample}]}, tmp_path / "c"
            )
            assert "error" not in read, read
            values = read["steps"][0]["values"]
            # The watchdog's verdict waits for its audit, which reads in the line's spare time.
            waiting = {n: v["status"] for n, v in values.items() if v["status"] != "Good"}
            assert all(n.endswith("/WatchdogVerdict") for n in waiting), waiting

            quiet = await _window(api)
            count = {**plan, "steps": [{"op": "count", "nodes": nodes, "seconds": WINDOW_S + 6}]}
            clients = [await start_plan(count, tmp_path / f"c{i}") for i in range(CLIENTS)]
            for client in clients:
                await subscribed(client)
            loaded = await _window(api)
            reports = [await finished(client) for client in clients]
            daemon.check_alive()

    assert len(names) > 1, names
    for report in reports:
        assert "error" not in report, report
        (counted,) = report["steps"]
        # Each drive's speed changes at every poll: a stream of changes, not a snapshot.
        assert counted["count"] > len(nodes), counted
    for window in (quiet, loaded):
        starved = {name: n for name, n in window["answered"].items() if n < 2}
        assert not starved, f"drives answered less than twice in {WINDOW_S} s: {starved}"
    print(
        f"rate {quiet['rate']:.1f} -> {loaded['rate']:.1f}/s "
        f"({loaded['rate'] / quiet['rate']:.3f}); slowest drive answered "
        f"{min(quiet['answered'].values())} -> {min(loaded['answered'].values())} times "
        f"in {WINDOW_S:g} s, with {CLIENTS} clients on {len(nodes)} variables"
    )


async def _ramp(api: httpx.AsyncClient, names: list[str]) -> None:
    """Send every drive towards 50 Hz: on its long ramp, each poll reads a new speed."""

    gate = asyncio.Semaphore(8)  # as a client that keeps within the server's connection limits

    async def ramp(name: str) -> str:
        async with gate:
            response = await api.post(
                f"/api/v1/drives/{name}/commands",
                json={"action": "set_reference", "frequency_hz": 50},
                headers={"Authorization": f"Bearer {OPERATOR}"},
            )
        response.raise_for_status()
        outcome: str = response.json()["outcome"]
        return outcome

    outcomes = await asyncio.gather(*(ramp(name) for name in names))
    assert set(outcomes) == {"done"}, outcomes
