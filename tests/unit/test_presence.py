"""The record of the drives answering, kept across restarts (fcmaster.presence).

What it keeps and when it writes, on real files; and a restart of the service in virtual
time with part of the plant unpowered: the drives that answered before are polled at once,
wherever their addresses sit among the absent ones.
"""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path

import pytest
import structlog

from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.bus.steps import DriveSlot
from fcmaster.config import parse
from fcmaster.presence import PresenceRecord, presence_path
from fcmaster.protocol.danfoss_fc import decode_telegram
from fcmaster.service import Service
from fcmaster.store_settings import MEMORY, StoreSettings
from tests.fakes import ScriptedTransport, VirtualClock
from tests.unit.bus.bench import DELAY_S, T0
from tests.unit.bus.fcdrive import FcDrive, FcLine


def slot(name: str, address: int, online: bool | None) -> DriveSlot:
    return DriveSlot(plan=DrivePlan(name=name, address=address), sequence=(), online=online)


def line(*drives: tuple[str, int]) -> LinePlan:
    plans = tuple(DrivePlan(name=name, address=address) for name, address in drives)
    return LinePlan(name="line1", port="x", drives=plans)


def test_the_record_lives_beside_the_journal_and_nowhere_without_one() -> None:
    assert presence_path(StoreSettings(path="/var/lib/fcmaster/journal.db")) == Path(
        "/var/lib/fcmaster/journal.db.present.json"
    )
    assert presence_path(StoreSettings(path=MEMORY)) is None
    assert presence_path(StoreSettings()) is None
    assert presence_path(None) is None


async def test_answering_drives_are_kept_demoted_ones_dropped_unheard_ones_unchanged(
    tmp_path: Path,
) -> None:
    path = tmp_path / "journal.db.present.json"
    record = PresenceRecord(path)
    record.update("line1", True, [slot("a", 1, True), slot("b", 2, True), slot("c", 3, None)])
    await record.save()
    assert json.loads(path.read_text()) == {"line1": {"a": 1, "b": 2}}
    # b was given up, c is still not heard from, a answers: b goes, nothing else changes
    record.update("line1", True, [slot("a", 1, None), slot("b", 2, False), slot("c", 3, None)])
    await record.save()
    assert json.loads(path.read_text()) == {"line1": {"a": 1}}
    # a line that is down (unplugged, or closed at shutdown) changes nothing
    record.update("line1", False, [slot("a", 1, False)])
    await record.save()
    assert json.loads(path.read_text()) == {"line1": {"a": 1}}
    again = PresenceRecord(path)
    assert again.answered_before(line(("a", 1), ("b", 2))) == {1}


async def test_nothing_is_written_while_nothing_changes(tmp_path: Path) -> None:
    path = tmp_path / "present.json"
    record = PresenceRecord(path)
    record.update("line1", True, [slot("a", 1, True)])
    await record.save()
    path.unlink()
    record.update("line1", True, [slot("a", 1, True)])
    await record.save()
    assert not path.exists()


def test_a_drive_moved_to_another_address_or_line_is_not_taken_for_the_one_recorded(
    tmp_path: Path,
) -> None:
    path = tmp_path / "present.json"
    path.write_text(json.dumps({"line1": {"a": 1, "b": 2}, "line2": {"c": 3}}))
    record = PresenceRecord(path)
    assert record.answered_before(line(("a", 1), ("b", 5), ("c", 3))) == {1}


async def test_a_record_that_cannot_be_written_is_told_once_and_written_when_it_can(
    tmp_path: Path,
) -> None:
    folder = tmp_path / "gone"
    record = PresenceRecord(folder / "journal.db.present.json")
    with structlog.testing.capture_logs() as logs:
        for address in (1, 2, 3):  # three changes, each tried and failed
            record.update("line1", True, [slot(f"d{address}", address, True)])
            await record.save()
    assert [entry["event"] for entry in logs] == ["presence.write_failed"]
    folder.mkdir()
    await record.save()
    assert json.loads((folder / "journal.db.present.json").read_text()) == {
        "line1": {"d1": 1, "d2": 2, "d3": 3}
    }


@pytest.mark.parametrize("text", ["{not json", "[1, 2]", '{"line1": {"a": "1"}}', ""])
def test_an_unreadable_record_is_a_first_start(tmp_path: Path, text: str) -> None:
    path = tmp_path / "present.json"
    path.write_text(text)
    assert PresenceRecord(path).answered_before(line(("a", 1))) == frozenset()


def test_a_missing_record_is_a_first_start(tmp_path: Path) -> None:
    assert PresenceRecord(tmp_path / "none.json").answered_before(line(("a", 1))) == frozenset()


# -- the service, restarted with the low addresses unpowered ------------------------------

PRESENT = frozenset({1, *range(111, 127)})


def fleet_config(journal: Path) -> str:
    drives = "\n".join(f"      - {{name: d{a}, address: {a}, control: bus}}" for a in range(1, 127))
    return f"""
buses:
  - name: line1
    port: /dev/ttyTEST
    baudrate: 115200
    timeout_s: 0.1
    drives:
{drives}
journal:
  path: {journal}
"""


async def first_polls(
    journal: Path, run_s: float, *, cut: tuple[float, float] | None = None
) -> tuple[Service, dict[int, float]]:
    """Run the service ``run_s`` (virtual) and stop it; when each drive was first answered.

    ``cut``: from when until when (seconds after the start) the line's cable is cut.
    """
    clock = VirtualClock(T0)
    drives = [FcDrive(a, silent=a not in PRESENT) for a in range(1, 127)]
    live = [d for d in drives if not d.silent]
    transports: list[ScriptedTransport] = []

    def scripted(_: object) -> ScriptedTransport:
        transports.append(ScriptedTransport(clock, FcLine(*drives), delay_s=DELAY_S))
        return transports[-1]

    service = Service(parse(fleet_config(journal)), clock=clock, transport_factory=scripted)
    task = asyncio.ensure_future(service.run(install_signals=False))
    if cut is not None:
        await clock.run_until(T0 + cut[0])
        for drive in live:
            drive.silent = True
        await clock.run_until(T0 + min(cut[1], run_s))
        for drive in live:
            drive.silent = False
    await clock.run_until(T0 + run_s)
    service.stop()
    await clock.complete(task, within=60.0)
    first: dict[int, float] = {}
    for sent in transports[0].sent:
        address = decode_telegram(sent.data, from_drive=False).address
        if address in PRESENT and sent.reply_at is not None:
            first.setdefault(address, sent.at - T0)
    return service, first


async def test_a_restart_polls_the_drives_that_answered_before_at_once(tmp_path: Path) -> None:
    journal = tmp_path / "journal.db"
    # The first start knows nothing: 111-126 wait for their one attempt behind 109 absent.
    _, first = await first_polls(journal, 150.0)
    assert set(first) == PRESENT
    assert min(first[a] for a in range(111, 127)) > 60.0
    recorded = json.loads((tmp_path / "journal.db.present.json").read_text())
    assert recorded == {"line1": {f"d{a}": a for a in sorted(PRESENT)}}
    # Restarted: every drive that answered before is answered within the first second.
    _, first = await first_polls(journal, 5.0)
    assert set(first) == PRESENT
    assert max(first.values()) < 1.0


async def test_a_line_fallen_silent_keeps_the_record_for_a_restart(tmp_path: Path) -> None:
    journal = tmp_path / "journal.db"
    record = tmp_path / "journal.db.present.json"
    present = {"line1": {f"d{a}": a for a in sorted(PRESENT)}}
    record.write_text(json.dumps(present))
    # The cable is cut 5 s after the start; the gateway is restarted a minute later.
    await first_polls(journal, 65.0, cut=(5.0, math.inf))
    assert json.loads(record.read_text()) == present
    # Started again before the cable is mended, 20 s later: the drives that answered
    # before are taken for a silent line and asked again at once when it answers, all
    # within a second (a first start would leave 111-126 a minute behind the absent ones).
    _, first = await first_polls(journal, 40.0, cut=(0.0, 20.0))
    assert set(first) == PRESENT
    assert min(first.values()) >= 20.0
    assert max(first.values()) < 21.0
