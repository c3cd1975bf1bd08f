"""`fcmaster events`: the journal of a config's daemon, newest last."""

from __future__ import annotations

import json
import sqlite3
import time
from pathlib import Path
from typing import Any

from fcmaster import config as config_module
from fcmaster.errors import FcmasterError, UsageError
from fcmaster.journal import KINDS, MAX_LIMIT, parse_since, read_file


def run(
    path: Path,
    *,
    since: str | None = None,
    drive: str | None = None,
    kind: str | None = None,
    limit: int = MAX_LIMIT,
    as_json: bool = False,
) -> int:
    """Print the records of ``path``'s journal that match, oldest first."""
    config = config_module.load(path)
    settings = config.journal
    if settings is None or settings.path is None:
        raise UsageError(
            f"{path} keeps no journal file (journal.path is not set: it is kept in memory); "
            "ask the running daemon instead: GET /api/v1/events"
        )
    try:
        after = None if since is None else parse_since(since, time.time())
    except ValueError as exc:
        raise UsageError(f"--since: {exc}") from None
    if kind is not None and kind not in KINDS:
        raise UsageError(f"--kind: {kind!r} is not one of {', '.join(KINDS)}")
    if not 1 <= limit <= MAX_LIMIT:
        raise UsageError(f"--limit: {limit} is outside 1-{MAX_LIMIT}")
    try:
        records = read_file(settings, since=after, kind=kind, drive=drive, limit=limit)
    except FileNotFoundError:
        raise FcmasterError(
            f"no journal at {settings.path} yet: the daemon creates it when it runs"
        ) from None
    except sqlite3.Error as exc:
        raise FcmasterError(f"cannot read the journal {settings.path}: {exc}") from None
    if as_json:
        print(json.dumps(records, indent=2, ensure_ascii=False))
        return 0
    for record in records:
        where = "/".join(part for part in (record["bus"], record["drive"]) if part) or "-"
        print(f"{record['at']}  {record['kind']:<9} {where:<24} {describe(record)}".rstrip())
    return 0


def describe(record: dict[str, Any]) -> str:
    """A record's own fields in a few words."""
    match record["kind"]:
        case "command":
            values = [
                f"{key} {record[key]}"
                for key in ("reference_pct", "parameter", "value")
                if key in record
            ]
            result = record.get("result")
            read = f" = {result['value']} {result['unit']}".rstrip() if result else ""
            reason = f" ({record['reason']})" if record.get("reason") else ""
            did = " ".join([record["action"], *values])
            return f"{did} by {record['actor'] or '-'} → {record['outcome']}{read}{reason}"
        case "alarm" | "warning":
            state = "raised" if record["active"] else "cleared"
            return f"{record['code']} {record['text']} {state}"
        case "watchdog":
            return f"{record['verdict']} (timeout {record['timeout_s']} s, {record['action']})"
        case "line_up" | "line_down":
            return str(record.get("reason") or "")
        case "reload":
            told = record.get("problems") or record.get("changes") or []
            return f"{record['outcome']}: {'; '.join(told) or 'nothing changed'}"
        case _:
            rest = {
                k: v for k, v in record.items() if k not in ("seq", "at", "kind", "bus", "drive")
            }
            return " ".join(f"{key}={value}" for key, value in rest.items())
