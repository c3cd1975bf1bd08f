"""A soak: the daemon on faulty simulated lines, commanded over HTTP, checked for the truth.

Run: ``python benchmarks/soak.py [--minutes 3] [--lines 4] [--drives 4] [--clients 4]``
(``--transactions 1000000`` runs until the lines have carried that many instead).

`fcmaster run` (a subprocess, as deployed) masters ``--lines`` lines of ``--drives``
simulated FC drives, each line on its own pseudo-terminal at 115200 baud, served by the
simulator in this process. Each line loses 1 % of the drives' replies and corrupts 0.5 %
(a byte changed: the checksum must catch it). Half the drives are ``control: bus``;
``--clients`` HTTP clients send them commands one after another — start, set_reference,
stop and parameter reads — each with an ``id``.

Checked, and reported:

- **transactions** the lines carried (``/api/v1/buses``: requests, replies, timeouts,
  checksum errors);
- **commands** sent and their outcomes; a command **without exactly one outcome**: an
  HTTP request that got no answer, or an answer whose ``id`` is not its own; and, per
  action, commands sent minus ``command.completed`` lines in the daemon's audit log (each
  command is to be audited once: anything but 0 is a finding);
- **untrue states**: twice a second every drive's state is read over HTTP, and its
  ``status_word`` and ``output_frequency_hz`` must be ones that simulated drive sent in a
  reply shortly before (recorded here as each reply left the drive, before any fault was
  applied to it) — a corrupted reply taken for a good one, or a reply put on the wrong
  drive, would show up here;
- the daemon's **RSS** at the start and at the end.

The machine's load goes with the figures. Linux only (``/proc``).
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import itertools
import json
import os
import random
import signal
import socket
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx

from fcmaster.clock import MonotonicClock, new_event_loop
from fcmaster.protocol.danfoss_fc.profile import decode_reference
from fcmaster.protocol.danfoss_fc.telegram import decode_telegram
from fcmaster.sim.build import build_line
from fcmaster.sim.faults import FaultPlan
from fcmaster.sim.pty import PtyServer
from fcmaster.sim.settings import DriveSettings, LineSettings

TOKEN = "soak-operator-0123456789abcdef"
BAUDRATE = 115200
NOMINAL_HZ = 50.0
HISTORY_S = 5.0  # how long a drive's replies are remembered for the state check
LATENESS_S = 2.0  # a state may be this much older than the reply it shows (HTTP, loaded CPU)


class Replies:
    """What each simulated drive said, by address, for the last HISTORY_S."""

    def __init__(self) -> None:
        self.by_drive: dict[tuple[str, int], collections.deque[tuple[float, int, float]]] = {}

    def wrap(self, line_name: str, drive: Any) -> None:
        history = self.by_drive.setdefault((line_name, drive.address), collections.deque())
        handle: Callable[[bytes, float], bytes | None] = drive.handle

        def recorded(frame: bytes, now: float) -> bytes | None:
            reply = handle(frame, now)
            if reply is not None:
                telegram = decode_telegram(reply, from_drive=True)
                hz = round(abs(decode_reference(telegram.pcd2)) * NOMINAL_HZ / 100.0, 3)
                stamp = time.time()
                history.append((stamp, telegram.pcd1, hz))
                while history and history[0][0] < stamp - HISTORY_S:
                    history.popleft()
            return reply

        drive.handle = recorded

    def had(self, line_name: str, address: int, word: int, hz: float, at: float) -> bool:
        """Whether the drive sent ``word`` and ``hz`` in one reply not long before ``at``."""
        return any(
            at - LATENESS_S <= t <= at + 0.05 and w == word and abs(h - hz) < 0.0015
            for t, w, h in self.by_drive.get((line_name, address), ())
        )


def _config(lines: list[tuple[str, Path]], drives: int, port: int) -> str:
    out = ["buses:"]
    for name, path in lines:
        out += [
            f"  - name: {name}",
            f"    port: {path}",
            f"    baudrate: {BAUDRATE}",
            "    drives:",
        ]
        for a in range(1, drives + 1):
            control = "bus" if a % 2 else "monitor"
            out.append(f"      - {{name: {name}-d{a}, address: {a}, control: {control}}}")
    out += [
        "http:",
        f"  listen: 127.0.0.1:{port}",
        "  tokens:",
        f"    - {{name: soak, role: operator, token: {TOKEN}}}",
        "logging: {level: info, format: json}",
    ]
    return "\n".join(out) + "\n"


def _rss_kib(pid: int) -> int:
    for row in Path(f"/proc/{pid}/status").read_text().splitlines():
        if row.startswith("VmRSS:"):
            return int(row.split()[1])
    return 0


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


class Tally:
    """Commands sent and what came of them."""

    def __init__(self) -> None:
        self.sent = 0
        self.sent_by_kind: collections.Counter[str] = collections.Counter()
        self.outcomes: collections.Counter[str] = collections.Counter()
        self.without_outcome: list[str] = []
        self.wrong_id: list[str] = []


async def _commander(
    client: httpx.AsyncClient, n: int, targets: list[str], tally: Tally, until: Callable[[], bool]
) -> None:
    rng = random.Random(n)
    for i in itertools.count():
        if until():
            return
        drive = rng.choice(targets)
        command_id = f"c{n}-{i}"
        kind = rng.choice(("start", "set_reference", "stop", "read"))
        tally.sent += 1
        tally.sent_by_kind[kind] += 1
        try:
            if kind == "read":
                response = await client.get(f"/api/v1/drives/{drive}/parameters/16-13")
                answer = response.json()
                answer["id"] = command_id  # a GET carries no id: it is its own answer
            else:
                body: dict[str, Any] = {"action": kind, "id": command_id}
                if kind != "stop":
                    body["frequency_hz"] = round(rng.uniform(10, 50), 1)
                response = await client.post(f"/api/v1/drives/{drive}/commands", json=body)
                answer = response.json()
        except (httpx.HTTPError, ValueError) as exc:
            tally.without_outcome.append(f"{command_id}: {exc!r}")
            continue
        if "outcome" not in answer:
            tally.without_outcome.append(f"{command_id}: {answer}")
            continue
        if answer.get("id") != command_id:
            tally.wrong_id.append(f"{command_id}: {answer.get('id')!r}")
        tally.outcomes[answer["outcome"]] += 1


async def _buses(client: httpx.AsyncClient) -> dict[str, dict[str, Any]]:
    response = await client.get("/api/v1/buses")
    return {b["name"]: b for b in response.json()}


def _transactions(buses: dict[str, dict[str, Any]]) -> dict[str, int]:
    keys = ("requests", "replies", "timeouts", "retries", "checksum_errors", "malformed")
    return {k: sum(int(b["stats"].get(k, 0)) for b in buses.values()) for k in keys}


async def soak(args: argparse.Namespace) -> dict[str, Any]:
    clock = MonotonicClock()
    replies = Replies()
    tmp = Path(tempfile.mkdtemp(prefix="fcmaster-soak-"))
    servers = []
    names = [f"l{i}" for i in range(args.lines)]
    for i, name in enumerate(names):
        line = build_line(
            LineSettings(baudrate=BAUDRATE, faults=FaultPlan(drop=0.01, corrupt=0.005, seed=i)),
            [(a, DriveSettings(response_delay_s=0.005)) for a in range(1, args.drives + 1)],
            clock=clock,
        )
        for drive in line.drives:
            replies.wrap(name, drive)
        servers.append(PtyServer(line, clock=clock, link=str(tmp / f"tty{name}")))
    for server in servers:
        server.open()
    port = _free_port()
    config = tmp / "soak.yaml"
    config.write_text(_config([(n, tmp / f"tty{n}") for n in names], args.drives, port))
    log = tmp / "daemon.log"
    with log.open("wb") as stderr:
        daemon = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "fcmaster", "run", "--config", str(config),
            stdout=asyncio.subprocess.DEVNULL, stderr=stderr,
        )  # fmt: skip
    headers = {"Authorization": f"Bearer {TOKEN}"}
    tally = Tally()
    untrue: list[str] = []
    checked = 0
    try:
        async with httpx.AsyncClient(
            base_url=f"http://127.0.0.1:{port}", headers=headers, timeout=30
        ) as client:
            for _ in range(600):
                try:
                    states = (await client.get("/api/v1/drives")).json()
                    if all(s["online"] for s in states):
                        break
                except httpx.HTTPError:
                    pass
                await asyncio.sleep(0.1)
            rss_start = _rss_kib(daemon.pid)
            first = _transactions(await _buses(client))
            started = time.monotonic()
            deadline = started + args.minutes * 60
            target = args.transactions
            done = asyncio.Event()

            def over() -> bool:
                return done.is_set()

            targets = [f"{n}-d{a}" for n in names for a in range(1, args.drives + 1, 2)]
            commanders = [
                asyncio.create_task(_commander(client, n, targets, tally, over))
                for n in range(args.clients)
            ]
            last_report = started
            while not done.is_set():
                await asyncio.sleep(0.5)
                now = time.monotonic()
                for state in (await client.get("/api/v1/drives")).json():
                    if state["status_word"] is None or state["updated_at"] is None:
                        continue
                    at = _parse_time(state["updated_at"])
                    checked += 1
                    if not replies.had(
                        state["bus"],
                        state["address"],
                        state["status_word"],
                        state["output_frequency_hz"],
                        at,
                    ):
                        untrue.append(
                            f"{state['name']} at {state['updated_at']}: word "
                            f"{state['status_word']:#06x}, {state['output_frequency_hz']} Hz"
                        )
                if now - last_report >= 30 or now >= deadline:
                    so_far = _transactions(await _buses(client))["requests"] - first["requests"]
                    print(f"  {now - started:7.0f} s: {so_far} transactions", file=sys.stderr)
                    last_report = now
                    if target is not None and so_far >= target:
                        done.set()
                if target is None and now >= deadline:
                    done.set()
            await asyncio.gather(*commanders)
            elapsed = time.monotonic() - started
            last = _transactions(await _buses(client))
            rss_end = _rss_kib(daemon.pid)
    finally:
        if daemon.returncode is None:
            daemon.send_signal(signal.SIGTERM)
            await daemon.wait()
        for server in servers:
            await server.close()
    audits = collections.Counter(
        record.get("command")
        for record in map(json.loads, log.read_text().splitlines())
        if record.get("event") == "command.completed" and record.get("actor") == "soak"
    )
    moved = {k: last[k] - first[k] for k in last}
    return {
        "seconds": round(elapsed, 1),
        "lines": args.lines,
        "drives_per_line": args.drives,
        "transactions": moved,
        "transactions_per_s": round(moved["requests"] / elapsed, 1),
        "commands": tally.sent,
        "outcomes": dict(tally.outcomes),
        "audited": sum(audits.values()),
        # each command should have exactly one command.completed line: 0 everywhere
        "sent_minus_audited_by_action": {
            kind: tally.sent_by_kind[kind] - audits.get(kind, 0)
            for kind in sorted(set(tally.sent_by_kind) | {k for k in audits if k})
        },
        "without_exactly_one_outcome": tally.without_outcome[:20] + tally.wrong_id[:20],
        "without_exactly_one_outcome_count": len(tally.without_outcome) + len(tally.wrong_id),
        "states_checked": checked,
        "untrue_states": untrue[:20],
        "untrue_state_count": len(untrue),
        "rss_kib_start": rss_start,
        "rss_kib_end": rss_end,
        "daemon_exit": daemon.returncode,
        "loadavg": os.getloadavg(),
        "log": str(log),
    }


def _parse_time(text: str) -> float:
    from datetime import datetime

    return datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, default=3.0)
    parser.add_argument("--transactions", type=int, help="run until this many instead")
    parser.add_argument("--lines", type=int, default=4)
    parser.add_argument("--drives", type=int, default=4)
    parser.add_argument("--clients", type=int, default=4)
    args = parser.parse_args()
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        print(json.dumps(runner.run(soak(args)), indent=2))


if __name__ == "__main__":
    main()
