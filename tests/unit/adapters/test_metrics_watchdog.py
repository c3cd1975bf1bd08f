"""/metrics: each commanded drive's watchdog verdict as a state set, and its timeout."""

from __future__ import annotations

from fcmaster.adapters.metrics import render
from fcmaster.bus.watchdog import Verdict, WatchdogReport
from fcmaster.state import DriveState


def _state(name: str, watchdog: WatchdogReport | None, control: str = "bus") -> DriveState:
    return DriveState(
        name=name, bus="line1", address=1, protocol="danfoss-fc", control=control,
        watchdog=watchdog,
    )  # fmt: skip


def test_each_verdict_is_one_sample_and_only_the_present_one_is_1() -> None:
    text = render(
        [
            _state("off", WatchdogReport(None, "off", Verdict.OFF)),
            _state("ok", WatchdogReport(2.5, "stop", Verdict.OK)),
            _state("unread", None),
            _state("monitor", None, control="monitor"),
        ],
        [],
    )
    samples = {
        line.rsplit(" ", 1)[0]: line.rsplit(" ", 1)[1]
        for line in text.splitlines()
        if line.startswith("fcmaster_drive_watchdog")
    }
    assert samples == {
        'fcmaster_drive_watchdog_verdict{bus="line1",drive="off",verdict="ok"}': "0",
        'fcmaster_drive_watchdog_verdict{bus="line1",drive="off",verdict="off"}': "1",
        'fcmaster_drive_watchdog_verdict{bus="line1",drive="off",verdict="too_short"}': "0",
        'fcmaster_drive_watchdog_verdict{bus="line1",drive="off",verdict="unknown"}': "0",
        'fcmaster_drive_watchdog_verdict{bus="line1",drive="ok",verdict="ok"}': "1",
        'fcmaster_drive_watchdog_verdict{bus="line1",drive="ok",verdict="off"}': "0",
        'fcmaster_drive_watchdog_verdict{bus="line1",drive="ok",verdict="too_short"}': "0",
        'fcmaster_drive_watchdog_verdict{bus="line1",drive="ok",verdict="unknown"}': "0",
        'fcmaster_drive_watchdog_timeout_seconds{bus="line1",drive="ok"}': "2.5",
    }
    assert text.count("# TYPE fcmaster_drive_watchdog_verdict gauge") == 1


def test_drive_state_json_carries_the_watchdog_once_it_is_read() -> None:
    unread = _state("a", None).to_json()
    assert "watchdog" not in unread
    read = _state("a", WatchdogReport(0.1, "stop", Verdict.TOO_SHORT)).to_json()
    assert read["watchdog"] == {"timeout_s": 0.1, "action": "stop", "verdict": "too_short"}


def test_a_new_verdict_is_published_at_once_and_only_once_per_change() -> None:
    from fcmaster.bus.plan import DrivePlan, LinePlan
    from fcmaster.protocol.codec import DriveStatus, Reply
    from fcmaster.state import DriveUpdated, Event, FleetState
    from tests.fakes import FakeClock

    drive = DrivePlan(name="a", address=1, control=True)
    line = LinePlan(name="line1", port="x", drives=(drive,))
    events: list[Event] = []
    clock = FakeClock()
    fleet = FleetState((line,), emit=events.append, clock=clock)
    status = DriveStatus(word=0x0607, running=False, fault=False, warning=False,
                         at_reference=False, reverse=None)  # fmt: skip
    fleet.drive_replied("line1", drive, Reply(address=1, status=status), clock.now(), None)
    events.clear()
    report = WatchdogReport(None, "off", Verdict.OFF)
    clock.time += 0.5  # well inside the heartbeat: only the verdict can publish
    fleet.drive_watchdog("line1", "a", report)
    state = fleet.get("line1", "a")
    assert state is not None
    assert state.to_json()["watchdog"]["verdict"] == "off"  # readers: at once
    updates = [e for e in events if isinstance(e, DriveUpdated)]
    assert [u.changed for u in updates] == [("watchdog",)]  # subscribers: at once
    assert updates[0].state.watchdog == report
    events.clear()
    clock.time += 0.5
    fleet.drive_replied("line1", drive, Reply(address=1, status=status), clock.now(), None)
    fleet.drive_watchdog("line1", "a", WatchdogReport(None, "off", Verdict.OFF))  # audit again
    assert not [e for e in events if isinstance(e, DriveUpdated)]  # same verdict: nothing
    ok = WatchdogReport(2.0, "stop", Verdict.OK)
    fleet.drive_watchdog("line1", "a", ok)
    updates = [e for e in events if isinstance(e, DriveUpdated)]
    assert [(u.changed, u.state.watchdog) for u in updates] == [(("watchdog",), ok)]
