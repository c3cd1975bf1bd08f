"""Which drives were answering, kept across restarts, so a restart polls them at once.

A line opened with most of its drives unknown tries each one it has not heard from in the
probes' share of the line (see :mod:`fcmaster.bus.rotation`), so the drives that answer keep
their poll rate. That alone cannot tell a live drive at address 126 from the absent ones
before it: with 110 absent drives and a 0.1 s reply timeout it would wait minutes for its
first poll, and its control-word watchdog would stop the motor. A gateway restarted with
part of the plant unpowered knows better: the drives that answered before it stopped are
almost always the ones that answer after. This record keeps them, per line, by name and
address, in a small JSON file beside the journal, and a line opens with them polled as
present (``answered_before``); one now gone is demoted after ``offline_after`` misses, as
any drive that stops answering.

What counts: a drive the line hears is present; one the line gave up on (demoted) is not;
one not heard since the line opened keeps what the record said, and so does every drive of
a line that is down or silent (everything that answered fell quiet together: a cable, the
adapter, a feeder), so an unplugged adapter, a cut cable or the shutdown's closing of the
ports never empties the record: a restart before the line is mended still polls those
drives first once it is. It is written only when it changes (a drive came or went), atomically
(a new file renamed over the old, synced first), off the event loop.
"""

from __future__ import annotations

import asyncio
import json
import os
import time
from collections.abc import Iterable
from pathlib import Path

import structlog

from fcmaster.bus.plan import LinePlan
from fcmaster.bus.steps import DriveSlot
from fcmaster.store import REPEAT_ERROR_S
from fcmaster.store_settings import MEMORY, StoreSettings

__all__ = ["PresenceRecord", "presence_path"]

log = structlog.get_logger("fcmaster.presence")


def presence_path(journal: StoreSettings | None) -> Path | None:
    """The record's file, beside the journal's (None: the journal is kept in memory)."""
    if journal is None or journal.path in (None, MEMORY):
        return None
    path = Path(journal.path)
    return path.with_name(path.name + ".present.json")


class PresenceRecord:
    """The drives each line had answering, by name and address, kept in ``path``."""

    def __init__(self, path: Path | None) -> None:
        """Read the record in ``path`` (None: kept in memory only, as with no journal)."""
        self.path = path
        self._lines: dict[str, dict[str, int]] = _read(path) if path is not None else {}
        self._saved = _encode(self._lines)
        self._failing = False  # the last write failed
        self._told_at = -REPEAT_ERROR_S  # when a failure was last logged (monotonic)

    def answered_before(self, plan: LinePlan) -> frozenset[int]:
        """The addresses of ``plan``'s drives that answered when the daemon last ran."""
        known = self._lines.get(plan.name, {})
        return frozenset(d.address for d in plan.drives if known.get(d.name) == d.address)

    def update(self, bus: str, hearing: bool, slots: Iterable[DriveSlot]) -> None:
        """Take what line ``bus`` has heard, if it is ``hearing``: up and not silent."""
        if not hearing:
            return
        known = self._lines.setdefault(bus, {})
        for slot in slots:
            if slot.online is True:
                known[slot.name] = slot.address
            elif slot.online is False:
                known.pop(slot.name, None)

    async def save(self) -> None:
        """Write the record if it changed since it was read or last written."""
        text = _encode(self._lines)
        if text == self._saved or self.path is None:
            return
        try:
            await asyncio.to_thread(_write, self.path, text)
        except OSError as exc:  # a full or read-only disk: the lines go on regardless
            # Tried again at every check; told when it begins to fail, at most every
            # REPEAT_ERROR_S, as the journal's writer does (not every second for months).
            if not self._failing and time.monotonic() - self._told_at >= REPEAT_ERROR_S:
                self._told_at = time.monotonic()
                log.warning("presence.write_failed", path=str(self.path), error=str(exc))
            self._failing = True
            return
        self._failing = False
        self._saved = text


def _encode(lines: dict[str, dict[str, int]]) -> str:
    return json.dumps(lines, sort_keys=True, indent=1)


def _read(path: Path) -> dict[str, dict[str, int]]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as exc:  # unreadable: start as if it were the first time
        log.warning("presence.unreadable", path=str(path), error=str(exc))
        return {}
    if not isinstance(data, dict):
        return {}
    return {
        str(bus): {str(n): a for n, a in drives.items() if type(a) is int}
        for bus, drives in data.items()
        if isinstance(drives, dict)
    }


def _write(path: Path, text: str) -> None:
    part = path.with_name(path.name + ".part")
    with open(part, "w", encoding="utf-8") as file:
        file.write(text)
        file.flush()
        os.fsync(file.fileno())
    os.replace(part, path)
