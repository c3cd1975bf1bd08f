"""SIGTERM with commands still arriving: `fcmaster run` as a subprocess on a simulated pty line.

The simulated FC drives run in this process, on a pseudo-terminal the daemon opens as its
serial port, so every telegram the daemon sends is seen here with the time it arrived. The
drives answer slowly (200 ms) so that the stop phase lasts long enough for clients to keep
sending commands into it. Then: after SIGTERM nothing but stops goes on the wire (at most
the one telegram already on its way), every control drive gets its stop, and every HTTP
client gets a JSON outcome — ``cancelled``, "fcmaster is shutting down", for the ones that
arrived too late — and never a 500.
"""

from __future__ import annotations

import asyncio
import itertools
import signal
import time
from datetime import datetime
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
from tests.integration.daemon_harness import EXIT_S, child, get_json, until
from tests.integration.ports import free_port

OPERATOR = "operator-token-0123456789abcdef"
ADDRESSES = (1, 2, 3, 4)
CONFIG = """
buses:
  - name: slow
    port: {port}
    baudrate: 19200
    response_delay_ms: 300
    drives:
{drives}
http:
  listen: 127.0.0.1:{http}
  tokens:
    - {{name: ops, role: operator, token: {token}}}
on_shutdown: stop
logging: {{format: json}}
"""


class Wire:
    """Every telegram the daemon sent, with when its last byte arrived here."""

    def __init__(self) -> None:
        self.framer = FcFramer()
        self.telegrams: list[tuple[float, int, int]] = []  # (time, address, control word)

    def heard(self, data: bytes) -> None:
        self.framer.feed(data)
        while (piece := self.framer.next_frame()) is not None:
            if isinstance(piece, Frame):
                telegram = decode_telegram(piece.data, from_drive=False)
                self.telegrams.append((time.monotonic(), telegram.address, telegram.pcd1))


def _story(wire: Wire, signalled: float, events: list[dict[str, Any]]) -> str:
    """What the wire and the daemon did from SIGTERM on, for a failure message in full.

    Every telegram heard after the signal (ms after it, address, control word) and every
    event the daemon logged from its ``service.stopping`` on, but the clients' commands
    ended "shutting down" (only counted) and the lines' frame dumps.
    """
    heard = [
        f"  +{(at - signalled) * 1000:7.1f} ms  drive {address}  word {word:#06x}"
        f"{'  (run)' if _runs(word) else ''}"
        for at, address, word in wire.telegrams
        if at > signalled
    ]
    stopping = next((i for i, e in enumerate(events) if e["event"] == "service.stopping"), 0)
    told, cancelled = [], 0
    for event in events[stopping:]:
        if event.get("reason") == "fcmaster is shutting down":
            cancelled += 1
            continue
        shown = {k: v for k, v in event.items() if k not in ("recent_frames", "port", "bus")}
        told.append(f"  {shown}")
    return "\n".join(
        [
            f"{len(wire.telegrams)} telegrams heard, {len(heard)} after SIGTERM:",
            *heard,
            f"the daemon from service.stopping on ({cancelled} 'shutting down' left out):",
            *told,
        ]
    )


def _runs(word: int) -> bool:
    """Whether a control word asks the motor to run (valid data, start, no stop of any kind)."""
    needed = ControlWord.DATA_VALID | ControlWord.START | ControlWord.NO_COAST
    return word & (needed | ControlWord.NO_QUICK_STOP) == needed | ControlWord.NO_QUICK_STOP


async def test_after_sigterm_only_stops_reach_the_wire_and_every_client_gets_an_outcome(
    tmp_path: Path,
) -> None:
    clock = MonotonicClock()
    line = build_line(
        LineSettings(baudrate=19200),
        [(a, DriveSettings(response_delay_s=0.2)) for a in ADDRESSES],
        clock=clock,
    )
    wire = Wire()
    pass_on = line.write

    def record(data: bytes) -> None:
        wire.heard(data)
        pass_on(data)

    line.write = record  # type: ignore[method-assign]
    http = free_port()
    link = tmp_path / "ttySLOW"
    drives = "\n".join(f"      - {{name: pump-{a}, address: {a}, control: bus}}" for a in ADDRESSES)
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(port=link, drives=drives, http=http, token=OPERATOR))
    headers = {"Authorization": f"Bearer {OPERATOR}", "Connection": "close"}

    async with (
        asyncio.timeout(120),
        PtyServer(line, clock=clock, link=str(link)),
        child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
        httpx.AsyncClient(base_url=f"http://127.0.0.1:{http}", headers=headers) as client,
    ):

        async def online() -> bool:
            states = await get_json(client, "/api/v1/drives")
            return all(s["online"] for s in states)

        await until(online, "every drive online", alive=daemon, timeout_s=60)
        for a in ADDRESSES:
            started = await client.post(
                f"/api/v1/drives/pump-{a}/commands", json={"action": "start", "frequency_hz": 30}
            )
            assert started.json()["outcome"] == "done", started.text

        answers: list[tuple[float, Any]] = []
        dropped: list[tuple[float, str]] = []
        sigterm_at: list[float] = []

        async def sender(n: int) -> None:
            for i in itertools.count():
                if daemon.process.returncode is not None:
                    return
                hz = 20 + (i + n) % 20
                body = {"action": "start" if i % 2 else "set_reference", "frequency_hz": hz}
                sent_at, sent_wall = time.monotonic(), time.time()
                try:
                    response = await client.post(
                        f"/api/v1/drives/pump-{1 + (i + n) % 4}/commands", json=body, timeout=30
                    )
                except httpx.ConnectError:  # the listener is closed: nothing was accepted
                    await asyncio.sleep(0.02)
                    continue
                except httpx.TransportError as exc:  # see below: only as the listener closes
                    dropped.append((sent_wall, repr(exc)))
                    continue
                answers.append((sent_at, response))

        senders = [asyncio.create_task(sender(n)) for n in range(8)]
        await asyncio.sleep(1.5)
        sigterm_at.append(time.monotonic())
        daemon.process.send_signal(signal.SIGTERM)
        code = await asyncio.wait_for(daemon.process.wait(), EXIT_S + 10)
        await asyncio.gather(*senders)
        assert code == 0, daemon.tail()

    signalled = sigterm_at[0]
    # every client got a JSON outcome, none a 500
    assert answers
    for _, response in answers:
        assert response.headers["content-type"] == "application/json", response.text
        assert response.status_code in (200, 409, 503, 504), response.text
        assert "outcome" in response.json()
    late = [r.json() for t, r in answers if t > signalled]
    assert {"outcome": "cancelled", "reason": "fcmaster is shutting down"} in late
    # on the wire: after SIGTERM at most the telegram already on its way asked for a motion;
    # from the first stop on, nothing did, and every drive got its stop
    after = [(address, word) for at, address, word in wire.telegrams if at > signalled]
    stops = [i for i, (_, word) in enumerate(after) if not _runs(word)]
    events = daemon.log_events()
    story = _story(wire, signalled, events)
    assert stops, story
    first_stop = stops[0]
    assert first_stop <= 1, story
    assert [w for _, w in after[first_stop:] if _runs(w)] == [], story
    assert {address for address, _ in after[first_stop:]} >= set(ADDRESSES), story
    # A request is dropped unanswered only when it was still in the kernel's queue of
    # connections the server had not taken yet as it stopped listening (reset); one the
    # server had taken is always answered.
    (closing,) = [e for e in events if e["event"] == "http.closing"]
    closing_at = datetime.fromisoformat(closing["timestamp"].replace("Z", "+00:00")).timestamp()
    assert [d for d in dropped if d[0] < closing_at - 0.5] == []
    assert len(dropped) <= 8
    assert not [e for e in events if e.get("level") in ("error", "critical") or "exception" in e], (
        story
    )
