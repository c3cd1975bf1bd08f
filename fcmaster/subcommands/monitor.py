"""`fcmaster monitor`: a running daemon's fleet as a live terminal table.

It follows the daemon's WebSocket stream (``/api/v1/stream``): the first message is a
snapshot of every drive and line, later ones replace one drive's state or one line's
statistics. The table is redrawn at most every ``interval_s`` with plain ANSI (cursor home,
clear to end), and only when something changed. A lost connection is retried with backoff
while the last table stays on screen, marked stale; ``--once`` prints one table and exits.
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import sys
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any, TextIO
from urllib.parse import urlunsplit

from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus, WebSocketException

from fcmaster.clock import Clock, MonotonicClock
from fcmaster.errors import FcmasterError, UsageError
from fcmaster.subcommands.urls import daemon_url

_HOME, _CLEAR_LINE, _CLEAR_BELOW = "\x1b[H", "\x1b[K", "\x1b[J"
_RED, _YELLOW, _GREEN, _DIM, _BOLD, _RESET = (
    "\x1b[31m",
    "\x1b[33m",
    "\x1b[32m",
    "\x1b[2m",
    "\x1b[1m",
    "\x1b[0m",
)


def stream_url(url: str) -> str:
    """``http://host:8080`` (or ws://…) → ``ws://host:8080/api/v1/stream``."""
    parts = daemon_url(url, ("http", "https", "ws", "wss"))
    scheme = {"http": "ws", "https": "wss", "ws": "ws", "wss": "wss"}[parts.scheme]
    path = parts.path.rstrip("/")
    if not path.endswith("/api/v1/stream"):
        path += "/api/v1/stream"
    return urlunsplit((scheme, parts.netloc, path, parts.query, ""))


@dataclass(slots=True)
class Fleet:
    """What the stream has said so far."""

    drives: dict[str, dict[str, Any]] = field(default_factory=dict)
    buses: dict[str, dict[str, Any]] = field(default_factory=dict)
    connected: bool = False
    note: str = ""

    def apply(self, message: dict[str, Any]) -> bool:
        """Fold one stream message in; whether the table changed."""
        kind = message.get("type")
        if kind == "snapshot":
            self.drives = {d["name"]: d for d in message.get("drives", [])}
            self.buses = {b["name"]: b for b in message.get("buses", [])}
            return True
        if kind == "drive":
            drive = message["drive"]
            self.drives[drive["name"]] = drive
            return True
        if kind == "line":
            bus = self.buses.setdefault(message["bus"], {"name": message["bus"]})
            bus["up"] = message.get("up", bus.get("up"))
            if message.get("stats") is not None:
                bus["stats"] = message["stats"]
            return True
        if kind == "dropped":
            self.note = f"{message.get('count', '?')} events missed (this terminal fell behind)"
            return True
        return False


def _paint(text: str, color: str, *, enabled: bool) -> str:
    return f"{color}{text}{_RESET}" if enabled and color else text


def _state(drive: dict[str, Any]) -> tuple[str, str]:
    if not drive.get("online"):
        return "offline", _DIM
    direction = "rev" if drive.get("direction") == "reverse" else "fwd"
    words = [f"run {direction}" if drive.get("running") else "stop"]
    color = _GREEN if drive.get("running") else ""
    if drive.get("warning"):
        words.append("WARN")
        color = _YELLOW
    if drive.get("fault"):
        words.append("FAULT")
        color = _RED
    return " ".join(words), color


def _age(updated_at: str | None, now: float) -> str:
    if not updated_at:
        return "–"
    try:
        seconds = now - datetime.fromisoformat(updated_at.replace("Z", "+00:00")).timestamp()
    except ValueError:
        return "?"
    return f"{max(0.0, seconds):.0f}s" if seconds < 100 else f"{seconds / 60:.0f}m"


def _oldest_reading(drive: dict[str, Any]) -> str | None:
    """The age the row shows: its frequency's reading when that is older than the status."""
    times = [t for t in (drive.get("updated_at"), drive.get("output_frequency_updated_at")) if t]
    return min(times) if times else None  # RFC 3339 UTC with ms: text order is time order


def _number(value: Any, digits: int) -> str:
    return "–" if not isinstance(value, int | float) else f"{value:.{digits}f}"


def render_table(fleet: Fleet, *, now: float, width: int = 120, color: bool = False) -> str:
    """The fleet as text lines no wider than ``width``, its ages as of ``now`` (Unix time)."""
    lines: list[str] = []
    status = "live" if fleet.connected else "disconnected — retrying"
    title = f"fcmaster monitor · {len(fleet.drives)} drives · {status}"
    lines.append(_paint(title, _BOLD, enabled=color))
    for bus in fleet.buses.values():
        stats = bus.get("stats") or {}
        latency = stats.get("latency_s") or {}
        mean = latency.get("sum", 0) / latency["count"] * 1000 if latency.get("count") else None
        healthy = bool(bus.get("up"))
        up = _paint("up" if healthy else "DOWN", _GREEN if healthy else _RED, enabled=color)
        lines.append(
            f"  {bus['name']} {up}  req {stats.get('requests', '–')}  "
            f"timeouts {stats.get('timeouts', '–')}  checksum {stats.get('checksum_errors', '–')}"
            f"  noise {stats.get('noise_bytes', '–')}  util "
            f"{_number((stats.get('utilisation') or 0) * 100, 0)}%  "
            f"latency {_number(mean, 1)} ms"
        )
    name_w = max([5, *(len(n) for n in fleet.drives)])
    header = f"{'DRIVE':<{name_w}}  {'BUS':<8} {'ADR':>3}  {'STATE':<16} {'HZ':>7} {'REF%':>6}"
    lines.append("")
    lines.append(_paint(f"{header} {'AGE':>4}  ALARMS · WARNINGS", _BOLD, enabled=color))
    for drive in fleet.drives.values():
        state, tint = _state(drive)
        conditions = [f"{c['code']} {c['text']}" for c in drive.get("alarms", [])]
        conditions += [f"w{c['code']} {c['text']}" for c in drive.get("warnings", [])]
        row = (
            f"{drive['name']:<{name_w}}  {drive.get('bus', ''):<8.8} {drive.get('address', ''):>3}"
            f"  {state:<16} {_number(drive.get('output_frequency_hz'), 2):>7}"
            f" {_number(drive.get('reference_pct'), 1):>6} {_age(_oldest_reading(drive), now):>4}"
            f"  {'; '.join(conditions)}"
        )
        lines.append(_paint(row[:width], tint, enabled=color))
    if fleet.note:
        lines.append(_paint(fleet.note, _YELLOW, enabled=color))
    return "\n".join(lines)


async def run(
    url: str,
    token: str | None,
    *,
    once: bool = False,
    interval_s: float = 0.5,
    out: TextIO | None = None,
    clock: Clock | None = None,
) -> int:
    """Follow the daemon at ``url`` until interrupted (or, ``once``, print one table).

    ``token`` None: the one in ``$FCM_TOKEN``, if any. ``clock`` paces the redraws and
    reconnects and tells the readings' ages (default: the real one).
    """
    clock = clock or MonotonicClock()
    out = out or sys.stdout
    token = token or os.environ.get("FCM_TOKEN")
    target = stream_url(url)
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    fleet = Fleet()
    is_tty = out.isatty()
    backoff = 0.5
    changed = asyncio.Event()
    painter = (
        None if once else asyncio.create_task(_repaint(fleet, changed, out, interval_s, clock))
    )
    try:
        while True:
            try:
                async with connect(target, additional_headers=headers, open_timeout=5) as ws:
                    fleet.connected, backoff = True, 0.5
                    async for raw in ws:
                        if fleet.apply(json.loads(raw)):
                            changed.set()
                        if once:
                            table = render_table(fleet, now=clock.wall(), width=_width(is_tty))
                            print(table, file=out)
                            return 0
            except InvalidStatus as exc:
                status = exc.response.status_code
                raise UsageError(_refusal(url, target, status, bool(token))) from exc
            except (OSError, WebSocketException, TimeoutError) as exc:
                if once:
                    raise FcmasterError(f"cannot reach fcmaster at {url}: {exc}") from exc
                fleet.connected = False
                changed.set()
            await clock.sleep(backoff)
            backoff = min(backoff * 2, 10.0)
    finally:
        if painter is not None:
            painter.cancel()
            await asyncio.gather(painter, return_exceptions=True)


def _refusal(url: str, target: str, status: int, has_token: bool) -> str:
    """What an HTTP refusal of the stream means: a token problem, or not fcmaster there."""
    if status in (401, 403) and has_token:
        return (
            f"{url} does not accept this token (HTTP {status}): "
            "pass one it knows with --token or FCM_TOKEN"
        )
    if status in (401, 403):
        return f"{url} wants a viewer token (HTTP {status}): pass one with --token or FCM_TOKEN"
    return (
        f"{target} is not an fcmaster stream (HTTP {status}): check that --url is the "
        "daemon's HTTP address (its http.listen)"
    )


def _width(is_tty: bool) -> int:
    return shutil.get_terminal_size((120, 40)).columns if is_tty else 200


async def _repaint(
    fleet: Fleet, changed: asyncio.Event, out: TextIO, interval_s: float, clock: Clock
) -> None:
    is_tty = out.isatty()
    while True:
        await changed.wait()
        changed.clear()
        table = render_table(fleet, now=clock.wall(), width=_width(is_tty), color=is_tty)
        if is_tty:
            body = "".join(line + _CLEAR_LINE + "\n" for line in table.splitlines())
            out.write(_HOME + body + _CLEAR_BELOW)
        else:
            out.write(table + "\n\n")
        out.flush()
        await clock.sleep(interval_s)
