"""The watchdog audit end to end: `fcmaster run` against `fcmaster sim` on ptys.

Each simulated drive starts with the watchdog settings its line's ``simulation`` section
gives it (FC 8-03/8-04, Mitsubishi Pr.122, ENC F2.16). The daemon reads them when it adopts
the drives; the verdicts must show in the HTTP API and in the JSON log. Then the daemon
stops with ``on_shutdown: hold``: the drives whose watchdog works stop by themselves (FC
ramps to a stop, Mitsubishi and ENC trip), while the one whose watchdog is off keeps its
motor turning, as `fcmaster status` reads from the simulator afterwards.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import httpx

from tests.integration.daemon_harness import START_S, by_name, child, get_json, until
from tests.integration.ports import free_port

WATCHDOG_S = 1.0  # the working watchdogs' timeout
OPERATOR = "operator-token-0123456789abcdef"
RAMP_S = 3.0  # the simulated FC drive's factory 3-42 (from 50 Hz; they run at 30 Hz)

CONFIG = """
buses:
  - name: fc
    port: {fc}
    baudrate: 19200
    drives:
      - {{name: fc-off, address: 1, control: bus}}
      - {{name: fc-short, address: 2, control: bus}}
      - {{name: fc-ok, address: 3, control: bus}}
      - {{name: fc-written, address: 4, control: bus, watchdog: {{timeout_s: 1.5}}}}
      - {{name: fc-monitor, address: 5}}
    simulation:
      drives:
        1: {{running_hz: 30, parameters: {{"8-03": 60.0, "8-04": 0}}}}
        2: {{parameters: {{"8-03": 0.1, "8-04": 2}}}}
        3: {{parameters: {{"8-03": {watchdog}, "8-04": 2}}}}
        4: {{running_hz: 30}}
  - name: mits
    port: {mits}
    protocol: mitsubishi
    baudrate: 19200
    parity: E
    stopbits: 2
    drives:
      - {{name: mits-ok, address: 1, control: bus}}
    simulation:
      drives:
        1: {{running_hz: 30, parameters: {{"Pr.122": {watchdog}}}}}
  - name: enc
    port: {enc}
    protocol: enc
    baudrate: 9600
    parity: N
    drives:
      - {{name: enc-ok, address: 1, control: bus}}
    simulation:
      drives:
        1: {{running_hz: 30, parameters: {{"F2.16": {watchdog}}}}}
http:
  listen: 127.0.0.1:{port}
  anonymous: viewer
  tokens:
    - {{name: ops, role: operator, token: {operator}}}
metrics: {{enabled: true}}
on_shutdown: hold
logging: {{level: info, format: json}}
"""


async def _verdicts(client: httpx.AsyncClient) -> dict[str, dict[str, Any]] | None:
    drives = by_name(await get_json(client, "/api/v1/drives"))
    audited = {n: d["watchdog"] for n, d in drives.items() if "watchdog" in d}
    return audited if len(audited) == 6 else None


async def _status(port: Path, line: tuple[str, ...], address: int, log: Path) -> dict[str, Any]:
    args = ("status", "--port", str(port), *line, "--address", str(address), "--json")
    async with child(*args, log=log) as status:
        assert status.process.stdout is not None
        out = await asyncio.wait_for(status.process.stdout.read(), START_S)
        assert await status.process.wait() == 0, status.tail()
    state: dict[str, Any] = json.loads(out)
    return state


async def test_verdicts_reach_the_api_and_the_log_and_working_watchdogs_stop_the_motors(
    tmp_path: Path,
) -> None:
    ports = {name: tmp_path / f"tty{name.upper()}" for name in ("fc", "mits", "enc")}
    http_port = free_port()
    config = tmp_path / "plant.yaml"
    config.write_text(
        CONFIG.format(**ports, port=http_port, watchdog=WATCHDOG_S, operator=OPERATOR)
    )
    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        assert {(await sim.readline()).split()[0] for _ in range(3)} == set(ports)
        async with (
            child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
            httpx.AsyncClient(base_url=f"http://127.0.0.1:{http_port}", timeout=10) as client,
        ):
            verdicts = await until(lambda: _verdicts(client), "six verdicts", alive=daemon)
            # what the daemon's start cost each drive: measured, and shorter than any timeout
            gaps = {name: v.pop("restart_gap_s") for name, v in verdicts.items()}
            assert all(0.0 < gap < WATCHDOG_S for gap in gaps.values()), gaps
            assert verdicts == {
                "fc-off": {"timeout_s": None, "action": "off", "verdict": "off"},
                "fc-short": {"timeout_s": 0.1, "action": "stop", "verdict": "too_short"},
                "fc-ok": {"timeout_s": WATCHDOG_S, "action": "stop", "verdict": "ok"},
                # the simulated factory setting (8-04 Off) was written over at adoption
                "fc-written": {"timeout_s": 1.5, "action": "stop", "verdict": "ok"},
                "mits-ok": {"timeout_s": WATCHDOG_S, "action": "trip", "verdict": "ok"},
                "enc-ok": {"timeout_s": WATCHDOG_S, "action": "trip", "verdict": "ok"},
            }
            # A simulated FC drive found running would have been stopped long ago by a
            # working watchdog (its former master left it at power-up): fc-ok is started.
            started = await client.post(
                "/api/v1/drives/fc-ok/commands",
                json={"action": "start", "frequency_hz": 30},
                headers={"Authorization": f"Bearer {OPERATOR}"},
            )
            assert started.json()["outcome"] == "done", started.text
            drives = by_name(await get_json(client, "/api/v1/drives"))
            assert "watchdog" not in drives["fc-monitor"]  # monitor-only: never audited
            for name in ("fc-off", "fc-ok", "fc-written", "mits-ok", "enc-ok"):
                assert drives[name]["running"] is True, name
            metrics = (await client.get("/metrics")).text
            assert 'fcmaster_drive_watchdog_verdict{bus="fc",drive="fc-off",verdict="off"} 1' in (
                metrics
            )
            code, _ = await daemon.stop()
            assert code == 0, daemon.tail()

        warnings = {
            (e["event"], e["drive"]): e
            for e in daemon.log_events()
            if e["event"].startswith("drive.watchdog_")
        }
        off = warnings[("drive.watchdog_off", "fc-off")]
        assert off["level"] == "warning"
        assert "8-04" in off["fix"]
        short = warnings[("drive.watchdog_too_short", "fc-short")]
        assert short["level"] == "warning"
        assert short["timeout_s"] == 0.1
        assert ("drive.watchdog_written", "fc-written") in warnings
        assert not [
            key for key in warnings if key[0] == "drive.watchdog_off" and key[1] != "fc-off"
        ]

        # The gateway is gone. Past the watchdogs' time (and the FC ramp) the drives that
        # have one are at rest; the one whose watchdog is off still turns.
        await asyncio.sleep(WATCHDOG_S + RAMP_S * 30 / 50 + 1.0)
        fc_line = ("--baudrate", "19200")
        log = tmp_path / "status.log"
        for address in (3, 4):
            state = await _status(ports["fc"], fc_line, address, log)
            assert state["running"] is False, (address, state)
            assert state["output_frequency_hz"] == 0.0
        still = await _status(ports["fc"], fc_line, 1, log)
        assert still["running"] is True
        assert abs(still["output_frequency_hz"] - 30.0) < 0.5
        mits = await _status(ports["mits"], ("--protocol", "mitsubishi"), 1, log)
        assert mits["running"] is False
        assert mits["fault"] is True  # E.PUE: tripped, not stopped on a ramp
        enc = await _status(ports["enc"], ("--protocol", "enc"), 1, log)
        assert enc["running"] is False
        assert enc["fault"] is True  # fault 16, RS-485 communication
        assert (await sim.stop())[0] == 0
