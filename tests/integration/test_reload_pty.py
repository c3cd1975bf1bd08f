"""SIGHUP reloads `fcmaster run`'s config: two simulated lines on ptys, watched on the wire.

The simulated FC drives run in this process, each line on a pseudo-terminal the daemon opens
as its serial port, so every telegram the daemon sends is decoded here with the time it
arrived. A reload that adds a drive to one line leaves the other line's port open and its
polls going as before, and the running bus drive on the changed line keeps being told to
run; a broken file is refused whole and changes nothing; a new HTTP address moves the API.
"""

from __future__ import annotations

import asyncio
import itertools
import signal
import time
from collections.abc import AsyncIterator
from contextlib import AsyncExitStack, asynccontextmanager
from pathlib import Path
from typing import Any

import httpx

from fcmaster.clock import MonotonicClock
from fcmaster.protocol.danfoss_fc.framer import FcFramer
from fcmaster.protocol.danfoss_fc.profile import ControlWord
from fcmaster.protocol.danfoss_fc.telegram import decode_telegram
from fcmaster.protocol.framing import Frame
from fcmaster.sim.build import build_line
from fcmaster.sim.pty import PtyServer
from fcmaster.sim.settings import DriveSettings, LineSettings
from tests.integration.daemon_harness import Child, by_name, child, get_json, until
from tests.integration.ports import free_port

CONFIG = """
buses:
  - name: north
    port: {north}
    baudrate: 19200
    drives:
      - {{name: pump-1, address: 1, control: bus}}
{more}
  - name: south
    port: {south}
    baudrate: 19200
    drives:
      - {{name: fan-1, address: 5}}
      - {{name: fan-2, address: 6}}
      - {{name: fan-3, address: 7}}
http:
  listen: 127.0.0.1:{http}
  anonymous: viewer
metrics: {{enabled: true}}
"""
PUMP_2 = "      - {name: pump-2, address: 2}"
SOUTH = (5, 6, 7)


class Wire:
    """Every telegram the daemon sent on one line: (when it arrived, address, control word)."""

    def __init__(self) -> None:
        self.framer = FcFramer()
        self.telegrams: list[tuple[float, int, int]] = []

    def heard(self, data: bytes) -> None:
        self.framer.feed(data)
        while (piece := self.framer.next_frame()) is not None:
            if isinstance(piece, Frame):
                telegram = decode_telegram(piece.data, from_drive=False)
                self.telegrams.append((time.monotonic(), telegram.address, telegram.pcd1))

    def addresses(self, start: float, end: float) -> list[int]:
        return [a for t, a, _ in self.telegrams if start <= t <= end]

    def between(self, start: float, end: float, address: int) -> list[tuple[float, int]]:
        return [(t, word) for t, a, word in self.telegrams if start <= t <= end and a == address]


def _polled_in_turn(addresses: list[int], cycle: tuple[int, ...]) -> bool:
    """Whether ``addresses`` go round ``cycle`` without a break (a reopen starts it over)."""
    return len(addresses) > 2 * len(cycle) and all(
        cycle[(cycle.index(a) + 1) % len(cycle)] == b for a, b in itertools.pairwise(addresses)
    )


def _runs(word: int) -> bool:
    needed = ControlWord.DATA_VALID | ControlWord.START | ControlWord.NO_COAST
    return word & (needed | ControlWord.NO_QUICK_STOP) == needed | ControlWord.NO_QUICK_STOP


@asynccontextmanager
async def _lines(tmp_path: Path) -> AsyncIterator[dict[str, Wire]]:
    """North (drives 1, running at 30 Hz, and 2) and south (drive 5) on ptys, tapped."""
    clock = MonotonicClock()
    wires: dict[str, Wire] = {}
    async with AsyncExitStack() as stack:
        for name, drives in (
            ("north", [(1, DriveSettings(running_hz=30.0)), (2, DriveSettings())]),
            ("south", [(a, DriveSettings()) for a in SOUTH]),
        ):
            line = build_line(LineSettings(name=name, baudrate=19200), drives, clock=clock)
            wire = wires[name] = Wire()
            pass_on = line.write

            def record(data: bytes, wire: Wire = wire, pass_on: Any = pass_on) -> None:
                wire.heard(data)
                pass_on(data)

            line.write = record  # type: ignore[method-assign]
            link = str(tmp_path / f"tty{name.upper()}")
            await stack.enter_async_context(PtyServer(line, clock=clock, link=link))
        yield wires


def _write(config: Path, tmp_path: Path, http: int, *, more: str = "") -> None:
    config.write_text(
        CONFIG.format(
            north=tmp_path / "ttyNORTH", south=tmp_path / "ttySOUTH", http=http, more=more
        )
    )


async def _heard(wire: Wire, after: float, count: int, daemon: Child) -> float:
    """Wait until ``count`` telegrams came on ``wire`` after ``after``: when the last came."""

    async def enough() -> float | None:
        times = [t for t, _, _ in wire.telegrams if t > after]
        return times[count - 1] if len(times) >= count else None

    return await until(enough, f"{count} telegrams", alive=daemon)


async def _reloaded(client: httpx.AsyncClient, daemon: Child, count: int) -> dict[str, Any]:
    daemon.process.send_signal(signal.SIGHUP)

    async def done() -> dict[str, Any] | None:
        config: dict[str, Any] = (await get_json(client, "/api/v1/status"))["config"]
        return config if sum(config["reloads"].values()) >= count else None

    return await until(done, f"reload {count}", alive=daemon)


async def test_a_drive_added_to_one_line_leaves_the_other_polling_and_nothing_jolted(
    tmp_path: Path,
) -> None:
    http = free_port()
    config = tmp_path / "plant.yaml"
    _write(config, tmp_path, http)
    async with (
        asyncio.timeout(180),
        _lines(tmp_path) as wires,
        child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
        httpx.AsyncClient(base_url=f"http://127.0.0.1:{http}", timeout=10) as client,
    ):

        async def online() -> dict[str, dict[str, Any]] | None:
            drives = by_name(await get_json(client, "/api/v1/drives"))
            return drives if all(d["online"] for d in drives.values()) else None

        before = await until(online, "drives online", alive=daemon)
        assert set(before) == {"pump-1", "fan-1", "fan-2", "fan-3"}
        assert before["pump-1"]["running"] is True  # found running: adopted as it is
        first = (await get_json(client, "/api/v1/status"))["config"]
        assert first["last_reload"] is None

        start = time.monotonic()
        await _heard(wires["south"], start, 30, daemon)  # south going round, before the reload
        _write(config, tmp_path, http, more=PUMP_2)
        sighup = time.monotonic()
        status = await _reloaded(client, daemon, 1)
        assert status["last_reload"]["outcome"] == "applied", status
        assert status["last_reload"]["changes"] == ["north: drive pump-2 added"]
        assert status["hash"] != first["hash"]
        after = await until(online, "pump-2 online", alive=daemon)
        assert set(after) == {"pump-1", "pump-2", "fan-1", "fan-2", "fan-3"}
        settled = await _heard(wires["south"], time.monotonic(), 30, daemon)
        await _heard(wires["north"], time.monotonic(), 4, daemon)

        # South's polls went round its drives without a break, and its port stayed open;
        # the figures of the gaps are benchmarks/reload_gap.py's.
        assert _polled_in_turn(wires["south"].addresses(start, settled), SOUTH)
        north = wires["north"].between(start, time.monotonic(), 1)
        assert all(_runs(word) for _, word in north), "pump-1 was told something but run"
        assert wires["north"].between(sighup, time.monotonic(), 2)  # the new drive is polled
        events = [(e["event"], e.get("bus")) for e in daemon.log_events()]
        assert events.count(("bus.opened", "south")) == 1  # never reopened
        assert events.count(("bus.opened", "north")) == 1
        assert (await get_json(client, "/api/v1/drives/pump-1"))["running"] is True

        # A broken file: refused whole, the running config and lines stay.
        config.write_text(config.read_text().replace("address: 5", "address: 300"))
        broken_at = time.monotonic()
        status = await _reloaded(client, daemon, 2)
        last = status["last_reload"]
        assert last["outcome"] == "refused"
        assert last["changes"] == []
        assert any("buses[1].drives[0].address" in p for p in last["problems"]), last
        assert status["hash"] == (await get_json(client, "/api/v1/status"))["config"]["hash"]
        assert status["reloads"] == {"applied": 1, "refused": 1}
        heard = await _heard(wires["south"], broken_at, 30, daemon)
        assert _polled_in_turn(wires["south"].addresses(broken_at, heard), SOUTH)
        assert all(d["online"] for d in await get_json(client, "/api/v1/drives"))
        refused = [e for e in daemon.log_events() if e["event"] == "config.reload_refused"]
        assert refused[0]["level"] == "error"
        metrics = (await client.get("/metrics")).text
        assert f'fcmaster_config_info{{hash="{status["hash"]}"}} 1' in metrics
        assert 'fcmaster_config_reloads_total{outcome="refused"} 1' in metrics
        journal = await get_json(client, "/api/v1/events?kind=reload")
        assert [r["outcome"] for r in journal] == ["applied", "refused"]


async def test_a_changed_http_listener_moves_and_the_lines_stay(tmp_path: Path) -> None:
    http, moved = free_port(), free_port()
    config = tmp_path / "plant.yaml"
    _write(config, tmp_path, http)
    async with (
        asyncio.timeout(120),
        _lines(tmp_path) as wires,
        child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
        httpx.AsyncClient(base_url=f"http://127.0.0.1:{http}", timeout=10) as old,
        httpx.AsyncClient(base_url=f"http://127.0.0.1:{moved}", timeout=10) as new,
    ):

        async def online() -> bool:
            return all(d["online"] for d in await get_json(old, "/api/v1/drives"))

        await until(online, "drives online", alive=daemon)
        start = time.monotonic()
        await _heard(wires["south"], start, 30, daemon)
        _write(config, tmp_path, moved)
        daemon.process.send_signal(signal.SIGHUP)

        async def answered() -> dict[str, Any] | None:
            config: dict[str, Any] = (await get_json(new, "/api/v1/status"))["config"]
            return config if config["last_reload"] else None

        status = await until(answered, "the API at its new address", alive=daemon)
        assert status["last_reload"]["changes"] == ["http: restarted (http.listen changed)"]
        try:
            await old.get("/api/v1/status")
        except httpx.ConnectError:
            pass
        else:
            raise AssertionError("the old address still answers")
        heard = await _heard(wires["south"], time.monotonic(), 30, daemon)
        assert _polled_in_turn(wires["south"].addresses(start, heard), SOUTH)
        events = [(e["event"], e.get("bus")) for e in daemon.log_events()]
        assert events.count(("bus.opened", "south")) == 1  # never closed and opened again
        assert events.count(("bus.opened", "north")) == 1
        assert all(d["online"] for d in await get_json(new, "/api/v1/drives")), daemon.tail(40)
