"""The journal: what happened to the fleet, kept on disk across restarts.

Theory of operation
-------------------
The journal is a subscriber of the hub like any adapter, so it never slows a line: the hub
files events with its subscription, a task of its own turns each one worth keeping into a
:class:`~fcmaster.store.Row`, and a :class:`~fcmaster.store.BackgroundWriter` thread commits
them (see :mod:`fcmaster.store`: a full disk is one logged error, never a stalled loop).
The service adds what the hub does not carry: its own start and stop, and each reload.

Kinds, each with ``at``, ``bus`` and ``drive`` (None where it belongs to neither):

==============  ===========================================================================
``command``     an ended command, its audit: ``actor``, ``action``, ``outcome``, ``reason``,
                its values (``reference_pct``, ``parameter``, ``index``, ``value``) and what
                a read returned (``result``) or the drive's ``error``
``alarm``       ``code``, ``text``, ``active`` (raised or cleared); ``warning`` the same
``online``      a drive answered again; ``offline`` it stopped answering
``watchdog``    a drive's watchdog verdict changed: ``verdict``, ``timeout_s``, ``action``
``line_up``     a line's port opened; ``line_down`` it was lost (``reason``)
``reload``      ``outcome``, ``changes``, ``problems``
``start``       the daemon started (``lines``, ``drives``); ``stop`` it is stopping
==============  ===========================================================================

A record is read back as one flat JSON object: ``seq`` (increasing), ``at`` (RFC 3339),
``kind``, ``bus``, ``drive`` and the kind's fields.
"""

from __future__ import annotations

import asyncio
import json
import re
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import structlog

from fcmaster.drive_state import rfc3339
from fcmaster.hub import EventsDropped, Hub, Subscription
from fcmaster.state import (
    AvailabilityChanged,
    CommandCompleted,
    ConditionChanged,
    DriveUpdated,
    Event,
    LineChanged,
)
from fcmaster.store import BackgroundWriter, Row, SequenceStore, Stored
from fcmaster.store_settings import StoreSettings

__all__ = [
    "KINDS",
    "MAX_LIMIT",
    "Journal",
    "parse_since",
    "read_file",
    "record_json",
]

log = structlog.get_logger("fcmaster.journal")

KINDS = (
    "command", "alarm", "warning", "online", "offline", "watchdog", "line_up", "line_down",
    "reload", "start", "stop",
)  # fmt: skip
MAX_LIMIT = 1000
CLOSE_S = 2.0  # at shutdown, for the writer to commit what is queued
_JOURNAL_EVENTS = (
    CommandCompleted, ConditionChanged, AvailabilityChanged, LineChanged, DriveUpdated,
)  # fmt: skip
_DURATION = re.compile(r"^(\d+(?:\.\d+)?)([smhd])$")
_UNIT_S = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}


def _store(settings: StoreSettings, *, readonly: bool = False) -> SequenceStore:
    return SequenceStore(
        settings.path,
        table="journal",
        max_bytes=settings.max_bytes,
        max_age_s=settings.max_age_s,
        readonly=readonly,
    )


def parse_since(text: str, now: float) -> float:
    """``since`` as wall seconds: a time (RFC 3339, UTC unless it says) or an age (``2h``).

    ValueError with what is accepted when it is neither.
    """
    found = _DURATION.match(text.strip())
    if found:
        return now - float(found.group(1)) * _UNIT_S[found.group(2)]
    try:
        when = datetime.fromisoformat(text.strip().replace("Z", "+00:00"))
    except ValueError:
        raise ValueError(
            f"{text!r} is neither a time (2026-11-27T08:00:00Z) nor an age (30s, 15m, 2h, 7d)"
        ) from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    return when.timestamp()


def record_json(stored: Stored) -> dict[str, Any]:
    """One stored record as the flat JSON object readers get."""
    fields = json.loads(stored.body)
    return {
        "seq": stored.seq,
        "at": rfc3339(stored.at),
        "kind": stored.kind,
        "bus": stored.bus,
        "drive": stored.drive,
        **fields,
    }


def event_row(event: Event, at: float) -> Row | None:
    """The journal's record of a hub event, or None when it is not one to keep."""
    kind: str
    fields: dict[str, Any]
    match event:
        case CommandCompleted(command=command, result=result):
            kind = "command"
            fields = {"actor": command.actor, "action": command.action.value}
            fields.update(outcome=result.outcome.value, reason=result.reason)
            if command.reference_pct is not None:
                fields["reference_pct"] = command.reference_pct
            if command.parameter is not None:
                fields.update(parameter=command.parameter, index=command.index)
            if command.value is not None:
                fields["value"] = command.value
            answer = result.to_json()
            if "value" in answer:
                fields["result"] = {k: answer[k] for k in ("value", "unit", "raw")}
            if "error" in answer:
                fields["error"] = answer["error"]
        case ConditionChanged():
            kind = event.kind
            fields = {"code": event.code, "text": event.text, "active": event.active}
        case AvailabilityChanged():
            kind, fields = ("online" if event.online else "offline"), {}
        case LineChanged():
            if event.stats is not None:  # a statistics sample, not an event
                return None
            kind, fields = ("line_up" if event.up else "line_down"), {"reason": event.reason}
        case DriveUpdated(state=state, changed=changed):
            if "watchdog" not in changed or state.watchdog is None:
                return None
            kind, fields = "watchdog", state.watchdog.to_json()
        case _:  # pragma: no cover - the union is matched above
            return None
    return Row(at, kind, event.bus, event.drive, json.dumps(fields, separators=(",", ":")))


def _encode(item: tuple[float, Event]) -> Row | None:
    at, event = item
    return event_row(event, at)


class Journal:
    """The fleet's journal: fed from the hub, written off the loop, read back by filters.

    Use as ``async with Journal(settings, hub, wall=clock.wall):``.
    """

    def __init__(self, settings: StoreSettings, hub: Hub, *, wall: Callable[[], float]) -> None:
        self.settings = settings
        self._hub = hub
        self._wall = wall
        self.writer = BackgroundWriter(_store(settings), name="journal", encode=_encode, wall=wall)
        self._subscription: Subscription | None = None
        self._task: asyncio.Task[None] | None = None

    async def __aenter__(self) -> Journal:
        self.writer.start()
        self._subscription = self._hub.subscribe(kinds=_JOURNAL_EVENTS, max_events=10_000)
        self._task = asyncio.create_task(self._follow(self._subscription), name="journal")
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        task, subscription = self._task, self._subscription
        self._task = self._subscription = None
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
        if subscription is not None:
            subscription.close()
            while (event := subscription.get_nowait()) is not None:  # what came last
                self._keep(event)
        # The last records are written before the process ends. This waits (bounded) on the
        # loop: every line is closed by now, and a thread handed this would leave the loop
        # with nothing to wait for but it.
        self.writer.close(CLOSE_S)

    def note(
        self, kind: str, *, bus: str | None = None, drive: str | None = None, **fields: Any
    ) -> None:
        """Record something the hub does not carry (start, stop, reload)."""
        self.writer.put(Row(self._wall(), kind, bus, drive, json.dumps(fields)))

    async def _follow(self, subscription: Subscription) -> None:
        async for event in subscription:
            self._keep(event)

    def _keep(self, event: Event | EventsDropped) -> None:
        if isinstance(event, EventsDropped):
            self.writer.dropped += event.count
            log.warning("journal.events_dropped", count=event.count)
            return
        if isinstance(event, DriveUpdated) and "watchdog" not in event.changed:
            return  # most of them: dropped here rather than queued
        self.writer.put((self._wall(), event))  # made a row on the writer's thread

    async def read(
        self,
        *,
        since: float | None = None,
        kind: str | None = None,
        drive: str | None = None,
        limit: int = 100,
    ) -> list[dict[str, Any]]:
        """The newest ``limit`` records matching, oldest first (empty if the store is down)."""

        def work(store: SequenceStore) -> list[Stored]:
            if not store.is_open:
                return []
            return store.read(since=since, kind=kind, drive=drive, limit=limit, newest=True)

        stored = await asyncio.to_thread(self.writer.call, work)
        return [record_json(s) for s in stored]


def read_file(
    settings: StoreSettings,
    *,
    since: float | None = None,
    kind: str | None = None,
    drive: str | None = None,
    limit: int = MAX_LIMIT,
) -> list[dict[str, Any]]:
    """Records of the journal file ``settings.path`` (another process may be writing it).

    FileNotFoundError when the file does not exist (yet); sqlite3.Error when it is not one.
    """
    if settings.path is None:
        raise ValueError("the journal is kept in memory")
    if not Path(settings.path).exists():
        raise FileNotFoundError(settings.path)
    store = _store(settings, readonly=True)
    store.open()
    try:
        stored = store.read(since=since, kind=kind, drive=drive, limit=limit, newest=True)
    finally:
        store.close()
    return [record_json(s) for s in stored]
