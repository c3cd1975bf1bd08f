"""A line's drives changed under a running planner (a reload): nothing jolted, nothing lost."""

from __future__ import annotations

import dataclasses

from fcmaster.bus.commands import Outcome
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.protocol.drive import Motion
from tests.unit.bus.test_planner import (
    RUN_WORD,
    STOP,
    A,
    B,
    M,
    adopted,
    answer,
    planner,
    results,
    set_reference,
    take,
    telegram,
)


def _line(*drives: DrivePlan) -> LinePlan:
    return LinePlan(name="line1", port="test", drives=drives)


def test_a_running_drive_kept_by_a_reload_keeps_its_intent_and_the_round_goes_on() -> None:
    p = planner(A, M)
    adopted(p, "a", running=True, output_pct=60.0)
    adopted(p, "m")
    answer(p, running=True, output_pct=60.0)  # a's poll
    kept = p.slot("a")
    assert kept.intent is not None
    assert kept.intent.motion is Motion.RUN
    assert take(p).slot is p.slot("m")  # the round is at m; a is next
    monitored = dataclasses.replace(A, monitor=("16-14",), max_frequency_hz=45.0)
    assert p.reconfigure(_line(monitored, M, B), "removed") == []
    assert p.slot("a") is kept  # its state, its intent: never jolted
    assert kept.plan is monitored
    # The drive the reload adds is not heard yet: one attempt in the probes' share, as at
    # the line's opening; unanswered, it waits there, and the round goes on where it was.
    attempt = take(p)
    assert attempt.slot is p.slot("b")
    p.on_failure(attempt, 0.0, "no reply")
    order = [take(p).slot for _ in range(2)]
    assert [s.name for s in order if s is not None] == ["a", "m"]
    again = take(p)
    assert again.slot is kept
    assert telegram(again).pcd1 == RUN_WORD  # told to run on, as before the reload


def test_a_removed_drive_s_queued_commands_end_cancelled_with_the_reason() -> None:
    p = planner(A, B)
    adopted(p, "b")
    tickets = [object(), object()]
    p.submit("b", set_reference(40.0), tickets[0])
    p.submit("a", STOP, tickets[1])
    ended = p.reconfigure(_line(A), "the drive was removed from the configuration")
    assert [(c.drive, c.result.outcome) for c in ended] == [("b", Outcome.CANCELLED)]
    assert ended[0].result.reason == "the drive was removed from the configuration"
    assert p.find("b") is None
    step = take(p)
    assert step.slot is p.slot("a")  # the stop of a is still queued and goes next
    assert step.pending is not None
    assert step.pending.command is STOP


def test_a_drive_at_a_new_address_is_a_new_drive_taken_over_as_at_start() -> None:
    p = planner(A)
    adopted(p, "a", running=True, output_pct=50.0)
    moved = dataclasses.replace(A, address=9)
    assert results(p.reconfigure(_line(moved), "removed")) == []
    slot = p.slot("a")
    assert slot.address == 9
    assert slot.intent is None  # not yet known: adopted from its first reply, never started
    step, _ = answer(p, running=True, output_pct=50.0)
    assert step.slot is slot
    assert slot.intent is not None
    assert slot.intent.motion is Motion.RUN  # adopted as it runs
