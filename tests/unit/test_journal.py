"""The journal: which fleet events it keeps, in what shape, and how it reads them back."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import pytest

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.bus.watchdog import Verdict, WatchdogReport
from fcmaster.hub import Hub
from fcmaster.journal import Journal, parse_since, read_file
from fcmaster.state import (
    AvailabilityChanged,
    CommandCompleted,
    ConditionChanged,
    DriveState,
    DriveUpdated,
    LineChanged,
)
from fcmaster.store_settings import StoreSettings


async def _settled(journal: Journal, count: int) -> None:
    async with asyncio.timeout(10):
        while journal.writer.written < count:  # noqa: ASYNC110  # a thread sets no event
            await asyncio.sleep(0.01)


async def test_each_kind_is_kept_flat_with_its_fields_and_stats_samples_are_not(
    tmp_path: Path,
) -> None:
    hub = Hub()
    settings = StoreSettings(path=str(tmp_path / "journal.db"))
    state = DriveState(name="pump-1", bus="line1", address=1, protocol="danfoss-fc", control="bus")
    watched = DriveState(
        name="pump-1", bus="line1", address=1, protocol="danfoss-fc", control="bus",
        watchdog=WatchdogReport(timeout_s=1.0, action="stop", verdict=Verdict.OK),
    )  # fmt: skip
    async with Journal(settings, hub, wall=time.time) as journal:
        journal.note("start", lines=1, drives=1)
        hub.publish(LineChanged(bus="line1", up=True))
        hub.publish(LineChanged(bus="line1", up=True, stats={"requests": 5}))  # not kept
        hub.publish(AvailabilityChanged(bus="line1", drive="pump-1", online=True))
        hub.publish(DriveUpdated(state, ("running",)))  # not kept
        hub.publish(DriveUpdated(watched, ("watchdog",)))
        hub.publish(
            ConditionChanged(
                bus="line1", drive="pump-1", kind="alarm", code=14, text="Earth fault", active=True
            )
        )
        hub.publish(
            CommandCompleted(
                bus="line1",
                drive="pump-1",
                command=Command(action=Action.START, reference_pct=80.0, actor="ops"),
                result=CommandResult(outcome=Outcome.DONE),
            )
        )
        await _settled(journal, 6)
        records = await journal.read(limit=100)
        assert [r["kind"] for r in records] == [
            "start", "line_up", "online", "watchdog", "alarm", "command",
        ]  # fmt: skip
        start, line_up, online, watchdog, alarm, command = records
        assert start["lines"] == 1
        assert start["bus"] is None
        assert (line_up["bus"], line_up["drive"]) == ("line1", None)
        assert (online["bus"], online["drive"]) == ("line1", "pump-1")
        assert watchdog["verdict"] == "ok"
        assert watchdog["timeout_s"] == 1.0
        assert (alarm["code"], alarm["text"], alarm["active"]) == (14, "Earth fault", True)
        assert {k: command[k] for k in ("actor", "action", "outcome", "reason")} == {
            "actor": "ops", "action": "start", "outcome": "done", "reason": "",
        }  # fmt: skip
        assert command["reference_pct"] == 80.0
        assert command["at"].endswith("Z")
        assert command["seq"] > alarm["seq"]
        assert [r["kind"] for r in await journal.read(kind="alarm")] == ["alarm"]
        assert len(await journal.read(drive="pump-1", limit=2)) == 2
    # Another process reads the file the daemon wrote.
    assert [r["kind"] for r in read_file(settings, drive="pump-1")] == [
        "online", "watchdog", "alarm", "command",
    ]  # fmt: skip


def test_since_takes_a_time_or_an_age() -> None:
    assert parse_since("2h", 10_000.0) == 10_000.0 - 7200.0
    assert parse_since("2026-11-27T08:00:00Z", 0.0) == parse_since("2026-11-27T08:00:00", 0.0)
    with pytest.raises(ValueError, match="neither a time"):
        parse_since("yesterday", 0.0)
