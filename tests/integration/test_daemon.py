"""`fcmaster run` as a subprocess against `fcmaster sim` on ptys, watched over its HTTP API.

Everything is real: the simulator serves each line on a pseudo-terminal linked at the bus's
``port`` path, the daemon opens those paths with its serial transport, and the test talks
to the daemon's HTTP API over a socket with bearer tokens. Losing a line is what an
unplugged USB adapter looks like: the simulator process serving that line goes away (its
pty closes and the device path disappears), then comes back.
"""

from __future__ import annotations

import asyncio
import json
import signal
from pathlib import Path
from typing import Any

import httpx

from tests.integration.daemon_harness import EXIT_S, START_S, Child, by_name, child, get_json, until
from tests.integration.ports import free_port

VIEWER = "viewer-token-0123456789abcdef"
OPERATOR = "operator-token-0123456789abcdef"

CONFIG = """
buses:
  - name: north
    port: {north}
    baudrate: 38400
    drives:
      - {{name: pump-1, address: 1, control: bus, nominal_frequency_hz: 50}}
      - {{name: pump-2, address: 2, control: bus, nominal_frequency_hz: 50}}
    simulation:
      drives:
        1: {{running_hz: 30}}
  - name: south
    port: {south}
    baudrate: 19200
    drives:
      - {{name: fan-1, address: 5, control: bus}}
http:
  listen: 127.0.0.1:{port}
  tokens:
    - {{name: scada, role: viewer, token: {viewer}}}
    - {{name: ops, role: operator, token: {operator}}}
"""


def _plant(tmp_path: Path) -> tuple[Path, Path, Path, int]:
    north, south = tmp_path / "ttyNORTH", tmp_path / "ttySOUTH"
    port = free_port()
    config = tmp_path / "plant.yaml"
    config.write_text(
        CONFIG.format(north=north, south=south, port=port, viewer=VIEWER, operator=OPERATOR)
    )
    return config, north, south, port


def _client(port: int, token: str | None = VIEWER) -> httpx.AsyncClient:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    return httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}", headers=headers, timeout=10)


async def _all_online(client: httpx.AsyncClient) -> dict[str, dict[str, Any]] | None:
    drives = by_name(await get_json(client, "/api/v1/drives"))
    return drives if all(d["online"] for d in drives.values()) else None


async def _expect_clean_exit(daemon: Child) -> None:
    code, took_s = await daemon.stop(signal.SIGTERM)
    assert code == 0, daemon.tail()
    assert took_s < EXIT_S
    events = [record["event"] for record in daemon.log_events()]  # JSON lines, not a TTY
    assert events.index("service.started") < events.index("service.stopped")


async def test_drive_states_follow_the_simulated_drives_and_an_operator_start_reaches_one(
    tmp_path: Path,
) -> None:
    config, north, _, port = _plant(tmp_path)
    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        assert {(await sim.readline()).split()[0] for _ in range(2)} == {"north", "south"}
        async with (
            child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
            _client(port) as viewer,
            _client(port, OPERATOR) as operator,
            _client(port, None) as anonymous,
        ):
            drives = await until(lambda: _all_online(viewer), "drive online", alive=daemon)
            assert set(drives) == {"pump-1", "pump-2", "fan-1"}
            pump_1, pump_2 = drives["pump-1"], drives["pump-2"]
            # Found running at 30 Hz in the simulator: adopted as it is, never jolted.
            assert pump_1["running"] is True
            assert abs(pump_1["output_frequency_hz"] - 30.0) < 1.0
            assert pump_2["running"] is False
            assert pump_2["output_frequency_hz"] == 0.0
            assert pump_2["updated_at"].endswith("Z")

            assert (await anonymous.get("/api/v1/drives")).status_code == 401
            command = {"action": "start", "frequency_hz": 40}
            refused = await viewer.post("/api/v1/drives/pump-2/commands", json=command)
            assert refused.status_code == 403  # a viewer never moves a motor
            assert (await get_json(viewer, "/api/v1/drives/pump-2"))["running"] is False

            started = await operator.post("/api/v1/drives/pump-2/commands", json=command)
            assert started.status_code == 200, started.text
            assert started.json()["outcome"] == "done"
            seen: list[float] = []

            async def at_40_hz() -> dict[str, Any] | None:
                state: dict[str, Any] = await get_json(viewer, "/api/v1/drives/pump-2")
                seen.append(state["output_frequency_hz"])
                return state if abs(state["output_frequency_hz"] - 40.0) < 0.5 else None

            pump_2 = await until(at_40_hz, "pump-2 at 40 Hz", alive=daemon)
            assert pump_2["running"] is True
            assert pump_2["reference_pct"] == 80.0  # 40 Hz of a 50 Hz nominal
            assert seen[0] < 39.5  # it ramped up after the start, it was not there already
            assert by_name(await get_json(viewer, "/api/v1/buses"))["north"]["up"] is True

            await _expect_clean_exit(daemon)

        # on_shutdown: hold — the motor the daemon started keeps turning after it exits.
        status = await _status(north, baudrate=38400, address=2, log=tmp_path / "status.log")
        assert status["running"] is True
        assert abs(status["output_frequency_hz"] - 40.0) < 0.5
        assert (await sim.stop())[0] == 0


async def _status(port: Path, *, baudrate: int, address: int, log: Path) -> dict[str, Any]:
    args = ("status", "--port", str(port), "--baudrate", str(baudrate))
    async with child(*args, "--address", str(address), "--json", log=log) as status:
        assert status.process.stdout is not None
        out = await asyncio.wait_for(status.process.stdout.read(), START_S)
        assert await status.process.wait() == 0, status.tail()
    state: dict[str, Any] = json.loads(out)
    return state


async def test_a_lost_line_goes_down_while_the_other_keeps_polling_and_then_recovers(
    tmp_path: Path,
) -> None:
    config, _, south, port = _plant(tmp_path)
    sim_args = ("sim", "--config", str(config), "--bus")
    async with (
        child(*sim_args, "north", log=tmp_path / "north.log") as north_sim,
        child(*sim_args, "south", log=tmp_path / "south.log") as south_sim,
    ):
        assert (await north_sim.readline()).split()[0] == "north"
        assert (await south_sim.readline()).split()[0] == "south"
        async with (
            child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
            _client(port) as viewer,
            _client(port, OPERATOR) as operator,
        ):
            await until(lambda: _all_online(viewer), "drive online", alive=daemon)

            # Unplug the south adapter: its pty closes and its device path disappears.
            code, _ = await south_sim.stop()
            assert code == 0
            assert not south.exists()

            async def south_down() -> dict[str, dict[str, Any]] | None:
                buses = by_name(await get_json(viewer, "/api/v1/buses"))
                fan = await get_json(viewer, "/api/v1/drives/fan-1")
                return None if buses["south"]["up"] or fan["online"] else buses

            buses = await until(south_down, "south down", alive=daemon)
            south_requests = buses["south"]["stats"]["requests"]
            north_requests = buses["north"]["stats"]["requests"]

            async def north_polled_on() -> dict[str, dict[str, Any]] | None:
                buses = by_name(await get_json(viewer, "/api/v1/buses"))
                return buses if buses["north"]["stats"]["requests"] >= north_requests + 50 else None

            buses = await until(north_polled_on, "north polling on", alive=daemon)
            assert buses["north"]["up"] is True
            assert buses["south"]["up"] is False
            assert str(south) in buses["south"]["stats"]["down_reason"]  # why it is down
            assert buses["south"]["stats"]["requests"] == south_requests  # nothing to send on
            drives = by_name(await get_json(viewer, "/api/v1/drives"))
            assert drives["pump-1"]["online"] is True
            assert drives["pump-2"]["online"] is True
            assert drives["fan-1"]["online"] is False
            # A command for a drive on the lost line is answered at once, not queued forever.
            lost = await operator.post("/api/v1/drives/fan-1/commands", json={"action": "stop"})
            assert lost.status_code == 503
            assert lost.json()["outcome"] == "cancelled"

            # Plug it back in: the daemon reopens the path by itself.
            async with child(*sim_args, "south", log=tmp_path / "south-2.log") as south_again:
                assert (await south_again.readline()).split()[0] == "south"

                async def south_back() -> dict[str, dict[str, Any]] | None:
                    buses = by_name(await get_json(viewer, "/api/v1/buses"))
                    fan = await get_json(viewer, "/api/v1/drives/fan-1")
                    up = buses["south"]["up"] and fan["online"]
                    return (
                        buses
                        if up and buses["south"]["stats"]["requests"] > south_requests
                        else None
                    )

                buses = await until(south_back, "south back", alive=daemon)
                assert buses["south"]["stats"]["reopens"] >= 1
                assert buses["south"]["stats"]["down_reason"] is None
                assert buses["north"]["up"] is True
                stopped = await operator.post(
                    "/api/v1/drives/fan-1/commands", json={"action": "stop"}
                )
                assert stopped.json()["outcome"] == "done"

                await _expect_clean_exit(daemon)
                assert (await south_again.stop())[0] == 0
        assert (await north_sim.stop())[0] == 0
