"""`fcmaster run` against `fcmaster sim` on a pty: one Modbus RTU line, a drive per profile.

The daemon reads each drive's communication watchdog from the registers its profile names
and judges it (the verdicts reach the HTTP API; one is written first, as its config asks),
and a drive of each family is started and
stopped through the HTTP API, each confirmed by its status word.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import httpx

from tests.integration.daemon_harness import START_S, by_name, child, get_json, until
from tests.integration.ports import free_port

OPERATOR = "operator-token-0123456789abcdef"
CONFIG = """
buses:
  - name: mb
    port: {port}
    protocol: modbus-rtu
    baudrate: 19200
    parity: E
    drives:
      - {{name: abb, address: 1, control: bus, profile: abb-drives,
          watchdog: {{timeout_s: 2.5, action: fault}}}}
      - {{name: v20, address: 2, control: bus, profile: sinamics-v20}}
      - {{name: atv, address: 3, control: bus, profile: altivar-cia402}}
      - {{name: yaskawa, address: 4, control: bus, profile: yaskawa-memobus}}
      - {{name: danfoss, address: 5, control: bus, profile: danfoss-fc-modbus}}
    simulation:
      drives:
        3: {{parameters: {{hr6005: 20, hr7002: 2}}}}
        4: {{parameters: {{hr1077: 20, hr1064: 1, hr1065: 1}}}}
        5: {{parameters: {{hr8029x2: 30, hr8039x2: 2}}}}
http:
  listen: 127.0.0.1:{http}
  anonymous: viewer
  tokens:
    - {{name: ops, role: operator, token: {operator}}}
on_shutdown: hold
logging: {{level: info, format: json}}
"""
NAMES = ("abb", "v20", "atv", "yaskawa", "danfoss")


async def _verdicts(client: httpx.AsyncClient) -> dict[str, dict[str, Any]] | None:
    drives = by_name(await get_json(client, "/api/v1/drives"))
    audited = {n: d["watchdog"] for n, d in drives.items() if "watchdog" in d}
    return audited if len(audited) == len(NAMES) else None


async def _status(port: Path, profile: str, address: int, log: Path) -> dict[str, Any]:
    args = ("status", "--port", str(port), "--protocol", "modbus-rtu", "--profile", profile)
    async with child(*args, "--address", str(address), "--json", log=log) as status:
        assert status.process.stdout is not None
        out = await asyncio.wait_for(status.process.stdout.read(), START_S)
        assert await status.process.wait() == 0, status.tail()
    state: dict[str, Any] = json.loads(out)
    return state


async def _drive(client: httpx.AsyncClient, name: str) -> dict[str, Any]:
    found: dict[str, Any] = await get_json(client, f"/api/v1/drives/{name}")
    return found


async def test_watchdog_verdicts_and_commands_of_every_profile(tmp_path: Path) -> None:
    port, http = tmp_path / "ttyMB", free_port()
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(port=port, http=http, operator=OPERATOR))
    auth = {"Authorization": f"Bearer {OPERATOR}"}
    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        assert (await sim.readline()).split()[0] == "mb"
        async with (
            child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
            httpx.AsyncClient(base_url=f"http://127.0.0.1:{http}", timeout=15) as client,
        ):
            verdicts = await until(lambda: _verdicts(client), "five verdicts", alive=daemon)
            # What the daemon's start cost each drive: its first telegram came soon after.
            gaps = {name: v.pop("restart_gap_s") for name, v in verdicts.items()}
            assert all(0.0 <= gap < 1.0 for gap in gaps.values()), gaps
            assert verdicts == {
                # written at adoption over the simulated factory setting (58.14 = no action)
                "abb": {"timeout_s": 2.5, "action": "fault", "verdict": "ok"},
                "v20": {"timeout_s": None, "action": "off", "verdict": "off"},  # P2014 = 0
                "atv": {"timeout_s": 2.0, "action": "ramp stop", "verdict": "ok"},
                "yaskawa": {"timeout_s": 2.0, "action": "coast to stop", "verdict": "ok"},
                "danfoss": {"timeout_s": 3.0, "action": "stop", "verdict": "ok"},
            }
            for name in NAMES:
                started = await client.post(
                    f"/api/v1/drives/{name}/commands",
                    json={"action": "start", "frequency_hz": 20},
                    headers=auth,
                )
                assert started.json()["outcome"] == "done", (name, started.text)

            async def at_speed() -> bool | None:
                states = [await _drive(client, n) for n in NAMES]
                fast = [abs((s["output_frequency_hz"] or 0) - 20) < 0.05 for s in states]
                return (all(s["running"] for s in states) and all(fast)) or None

            await until(at_speed, "every drive at 20 Hz", alive=daemon)
            stopped = await client.post(
                "/api/v1/drives/atv/commands", json={"action": "stop"}, headers=auth
            )
            assert stopped.json()["outcome"] == "done", stopped.text
            state = await _drive(client, "atv")
            assert state["protocol"] == "modbus-rtu"
            assert state["running"] is False
            code, _ = await daemon.stop()  # on_shutdown: hold
            assert code == 0, daemon.tail()

        # The gateway is gone. Past the watchdogs' time, the drives that have one tripped;
        # the SINAMICS V20, whose watchdog is off (P2014 = 0), still turns.
        await asyncio.sleep(3.0 + 0.5)
        log = tmp_path / "status.log"
        abb = await _status(port, "abb-drives", 1, log)
        assert abb["fault"] is True
        assert abb["running"] is False
        v20 = await _status(port, "sinamics-v20", 2, log)
        assert v20["running"] is True
        assert abs(v20["output_frequency_hz"] - 20.0) < 0.05
        yaskawa = await _status(port, "yaskawa-memobus", 4, log)
        assert yaskawa["fault"] is True
        assert (await sim.stop())[0] == 0
