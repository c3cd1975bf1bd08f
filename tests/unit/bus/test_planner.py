"""The planner, synchronously: what goes on the wire next, and how each command ends.

Plain tests of each rule, then a hypothesis state machine that drives a planner the way
the master does (a step goes out, commands arrive while it is in flight, the reply or the
timeout comes back) and checks the invariants after every move.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.stateful import (
    RuleBasedStateMachine,
    invariant,
    precondition,
    rule,
)

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.bus.plan import DrivePlan, LinePlan, OnStart
from fcmaster.bus.planner import Completion, Pending, Phase, Planner, Report, Step, StepKind
from fcmaster.protocol.codec import (
    Condition,
    ConditionReport,
    DriveError,
    DriveStatus,
    ParameterValue,
    Reply,
)
from fcmaster.protocol.danfoss_fc import ControlWord, Telegram, decode_telegram, encode_reference
from fcmaster.protocol.danfoss_fc.codec import ALARM_WORD, WARNING_WORD, FcCodec
from fcmaster.protocol.drive import DEFAULT_NOMINAL_HZ, pct_to_hz

A = DrivePlan(name="a", address=1, control=True)
B = DrivePlan(name="b", address=2, control=True)
M = DrivePlan(name="m", address=3)
STOP_WORD, RUN_WORD = 0x043C, 0x047C


def planner(*drives: DrivePlan, **options: Any) -> Planner:
    plan = LinePlan(name="line1", port="test", drives=drives)
    return Planner(dataclasses.replace(plan, **options), FcCodec())


def reply(
    address: int,
    *,
    running: bool = False,
    output_pct: float = 0.0,
    fault: bool = False,
    warning: bool = False,
    local: bool = False,
    value: ParameterValue | None = None,
    error: DriveError | None = None,
) -> Reply:
    word = 0x0207 | 0x0800 * running | 0x0008 * fault | 0x0080 * warning
    status = DriveStatus(
        word=word & ~0x0200 if local else word,
        running=running,
        fault=fault,
        warning=warning,
        at_reference=running,
        reverse=None if output_pct == 0 else output_pct < 0,
        accepts_bus_control=not local,
    )
    output_hz = pct_to_hz(output_pct, DEFAULT_NOMINAL_HZ)  # the planner's drives are at 50 Hz
    return Reply(
        address=address, status=status, output_frequency_hz=output_hz, value=value, error=error
    )


def telegram(step: Step) -> Telegram:
    return decode_telegram(step.exchange.request, from_drive=False)


def take(p: Planner, now: float = 0.0) -> Step:
    step = p.next_step(now)
    assert step is not None
    return step


def answer(p: Planner, now: float = 0.0, **state: Any) -> tuple[Step, Report]:
    """Take the next step and answer it as its drive (``state``: see :func:`reply`)."""
    step = take(p, now)
    assert step.slot is not None
    return step, p.on_reply(step, reply(step.slot.address, **state), now)


def results(*reports: Report | list[Completion]) -> list[Outcome]:
    ends: list[Outcome] = []
    for report in reports:
        completions = report.completions if isinstance(report, Report) else report
        ends += [c.result.outcome for c in completions]
    return ends


def start(pct: float | None = None) -> Command:
    return Command(action=Action.START, reference_pct=pct)


def set_reference(pct: float) -> Command:
    return Command(action=Action.SET_REFERENCE, reference_pct=pct)


STOP = Command(action=Action.STOP)


def adopted(p: Planner, name: str = "a", **state: Any) -> None:
    """Poll until drive ``name`` has answered once (and so is adopted)."""
    while True:
        step, _ = answer(p, **state)
        if step.slot is not None and step.slot.name == name:
            return


# -- the order of service ----------------------------------------------------------------


def test_idle_polls_rotate_over_the_drives_in_configured_order() -> None:
    p = planner(A, B, M)
    steps = [answer(p)[0] for _ in range(7)]
    assert [s.kind for s in steps] == [StepKind.POLL] * 7
    assert [s.exchange.address for s in steps] == [1, 2, 3, 1, 2, 3, 1]


def test_urgent_command_goes_before_earlier_commands_and_polls() -> None:
    p = planner(A, M)
    adopted(p)
    read = Command(action=Action.READ, parameter="16-13")
    assert p.submit("m", read, "read") == []
    assert p.submit("a", Command(action=Action.READ, parameter="16-14"), "read-a") == []
    assert p.submit("a", Command(action=Action.QUICK_STOP), "quick") == []
    steps = []
    for _ in range(3):
        step = take(p)
        assert step.pending is not None
        steps.append(step.pending.tickets)
        p.on_reply(step, reply(step.exchange.address), 0.0)
    assert steps == [["quick"], ["read"], ["read-a"]]
    assert take(p).kind is StepKind.POLL


def test_commands_are_served_in_arrival_order() -> None:
    p = planner(A, M)
    for n, parameter in enumerate(("16-13", "16-14", "16-30")):
        p.submit("m", Command(action=Action.READ, parameter=parameter), n)
    order = []
    while p.has_commands:
        step = take(p)
        order.append(telegram(step).pnu)
        p.on_reply(step, reply(3), 0.0)
    assert order == [1613, 1614, 1630]


def test_failed_command_is_retried_first_and_times_out_after_its_retries() -> None:
    p = planner(A, M, retries=2)
    p.submit("m", Command(action=Action.READ, parameter="16-13"), "read")
    attempts = []
    for n in range(3):
        step = take(p, float(n))
        assert step.pending is not None
        assert step.pending.tickets == ["read"]
        attempts.append(p.on_failure(step, float(n), "no reply"))
    assert results(*attempts) == [Outcome.TIMEOUT]
    assert attempts[-1].completions[0].result.reason == "no reply"
    assert take(p).kind is StepKind.POLL


def test_stop_submitted_between_retries_goes_first() -> None:
    p = planner(A, M)
    adopted(p)
    p.submit("m", Command(action=Action.READ, parameter="16-13"), "read")
    p.on_failure(take(p), 0.0, "no reply")
    p.submit("a", STOP, "stop")
    step = take(p)
    assert step.pending is not None
    assert step.pending.tickets == ["stop"]


def test_failed_idle_poll_is_not_retried() -> None:
    p = planner(A, M)
    step = take(p)
    p.on_failure(step, 0.0, "no reply")
    assert take(p).exchange.address == 3


def test_nothing_to_do_when_every_drive_is_demoted_until_the_next_probe() -> None:
    p = planner(A, M, offline_after=1, probe_interval_s=2.0)
    for _ in range(2):
        p.on_failure(take(p, 10.0), 10.0, "no reply")
    assert p.next_step(11.0) is None
    assert p.next_wakeup(11.0) == 12.0
    probe = take(p, 12.0)
    assert probe.kind is StepKind.PROBE
    assert p.next_wakeup(12.0) == 12.0  # the other drive's probe is due too


def test_next_wakeup_is_none_while_no_drive_is_demoted() -> None:
    assert planner(A, M).next_wakeup(0.0) is None


# -- demotion, probes, recovery ----------------------------------------------------------


def test_drive_is_demoted_after_offline_after_consecutive_failures() -> None:
    p = planner(M, offline_after=3, probe_interval_s=5.0)
    reports = [p.on_failure(take(p, t), t, "no reply") for t in (0.0, 1.0, 2.0)]
    assert [r.transitions for r in reports[:2]] == [[], []]
    ((transition,),) = [r.transitions for r in reports[2:]]
    assert (transition.drive, transition.online) == (M, False)
    assert p.next_step(6.9) is None
    probe = take(p, 7.0)
    assert (probe.kind, len(probe.exchange.request)) == (StepKind.PROBE, 8)
    assert (telegram(probe).pcd1, telegram(probe).pcd2) == (0, 0)


def test_a_reply_in_between_resets_the_failure_count() -> None:
    p = planner(M, offline_after=2)
    p.on_failure(take(p), 0.0, "no reply")
    p.on_reply(take(p), reply(3), 0.0)
    report = p.on_failure(take(p), 0.0, "no reply")
    assert report.transitions == []


def test_demoted_drive_is_probed_at_the_probe_interval_while_others_are_polled() -> None:
    p = planner(A, M, offline_after=1, probe_interval_s=1.0)
    probes, now = [], 0.0
    while now < 5.0:
        step = take(p, now)
        if step.exchange.address == 3:
            if step.kind is StepKind.PROBE:
                probes.append(now)
            p.on_failure(step, now, "no reply")
        else:
            p.on_reply(step, reply(1), now)
        now += 0.03
    assert len(probes) == 4
    assert all(1.0 <= b - a < 1.03 + 1e-9 for a, b in itertools.pairwise(probes))


def test_answered_probe_brings_the_drive_back_into_the_round() -> None:
    p = planner(A, M, offline_after=1, probe_interval_s=1.0)
    answer(p)
    p.on_failure(take(p), 0.0, "no reply")
    probe = take(p, 1.0)
    report = p.on_reply(probe, reply(3), 1.0)
    assert [(t.drive.name, t.online) for t in report.transitions] == [("m", True)]
    assert {take(p, 1.0).exchange.address for _ in range(2)} == {1, 3}


def test_running_drive_is_probed_without_a_command_and_adopted_again() -> None:
    p = planner(A, offline_after=1, probe_interval_s=1.0)
    answer(p, running=True, output_pct=50.0)
    assert telegram(take(p)).pcd1 == RUN_WORD
    p.on_failure(take(p), 0.0, "no reply")
    probe = take(p, 1.0)
    assert telegram(probe).pcd1 == 0
    p.on_reply(probe, reply(1), 1.0)  # it stopped meanwhile
    assert telegram(take(p, 1.0)).pcd1 == STOP_WORD


def test_stopped_drive_keeps_its_stop_word_through_demotion() -> None:
    p = planner(A, offline_after=1, probe_interval_s=1.0)
    answer(p, running=True, output_pct=50.0)
    p.submit("a", STOP, "stop")
    answer(p)
    p.on_failure(take(p), 0.0, "no reply")
    assert telegram(take(p, 1.0)).pcd1 == STOP_WORD


# -- control intent: adoption, commands, trips, resets ------------------------------------


def test_monitor_only_drive_is_never_commanded() -> None:
    p = planner(M)
    for _ in range(3):
        step, _ = answer(p, running=True, output_pct=50.0)
        assert (telegram(step).pcd1, telegram(step).pcd2) == (0, 0)
        assert not step.exchange.carries_control


@pytest.mark.parametrize(
    ("state", "word", "reference"),
    [
        pytest.param({"running": True, "output_pct": 37.5}, RUN_WORD, 37.5, id="running"),
        pytest.param({"running": True, "output_pct": -25.0}, RUN_WORD | 0x8000, 25.0, id="reverse"),
        pytest.param({"running": False}, STOP_WORD, 0.0, id="stopped"),
        pytest.param({"running": True, "fault": True}, STOP_WORD, 0.0, id="tripped"),
    ],
)
def test_first_reply_is_adopted(state: dict[str, Any], word: int, reference: float) -> None:
    p = planner(A)
    first, _ = answer(p, **state)
    assert (telegram(first).pcd1, first.exchange.carries_control) == (0, False)
    second = telegram(take(p))
    assert (second.pcd1, second.pcd2) == (word, encode_reference(reference))


def test_on_start_stop_commands_a_stop_before_anything_is_known() -> None:
    p = planner(dataclasses.replace(A, on_start=OnStart.STOP))
    first = take(p)
    assert (telegram(first).pcd1, first.exchange.carries_control) == (STOP_WORD, True)


def test_start_then_set_reference_keeps_running_at_the_new_reference() -> None:
    p = planner(A)
    adopted(p)
    p.submit("a", start(20.0), 1)
    step, report = answer(p, running=True, output_pct=20.0)
    assert (telegram(step).pcd1, telegram(step).pcd2) == (RUN_WORD, encode_reference(20.0))
    assert results(report) == [Outcome.DONE]
    p.submit("a", set_reference(30.0), 2)
    step, _ = answer(p, running=True, output_pct=30.0)
    assert (telegram(step).pcd1, telegram(step).pcd2) == (RUN_WORD, encode_reference(30.0))
    assert telegram(take(p)).pcd2 == encode_reference(30.0)


def test_reverse_and_forward_change_only_the_direction() -> None:
    p = planner(A)
    adopted(p, running=True, output_pct=40.0)
    p.submit("a", Command(action=Action.REVERSE), 1)
    step, _ = answer(p)
    assert telegram(step).pcd1 == RUN_WORD | ControlWord.REVERSE
    p.submit("a", Command(action=Action.FORWARD), 2)
    step, _ = answer(p)
    assert (telegram(step).pcd1, telegram(step).pcd2) == (RUN_WORD, encode_reference(40.0))


def test_relative_command_to_a_drive_not_yet_heard_first_learns_its_state() -> None:
    p = planner(A)
    p.submit("a", set_reference(30.0), "ref")
    learn = take(p)
    assert learn.kind is StepKind.COMMAND
    assert (telegram(learn).pcd1, telegram(learn).pke) == (0, None)
    assert p.on_reply(learn, reply(1, running=True, output_pct=45.0), 0.0).completions == []
    step, report = answer(p)
    assert (telegram(step).pcd1, telegram(step).pcd2) == (RUN_WORD, encode_reference(30.0))
    assert results(report) == [Outcome.DONE]


def test_trip_turns_the_intent_into_a_stop_and_reset_does_not_restart() -> None:
    p = planner(A)
    adopted(p, running=True, output_pct=50.0)
    answer(p, fault=True)
    assert telegram(take(p)).pcd1 == STOP_WORD
    p.submit("a", Command(action=Action.RESET), "reset")
    pulse, report = answer(p, fault=True)
    assert telegram(pulse).pcd1 == STOP_WORD | ControlWord.RESET
    assert results(report) == [Outcome.DONE]
    assert telegram(take(p)).pcd1 == STOP_WORD  # the pulse lasts one telegram


def test_trip_seen_in_the_reply_to_a_motion_command_still_stops() -> None:
    p = planner(A)
    adopted(p, running=True, output_pct=50.0)
    p.submit("a", set_reference(60.0), "ref")
    answer(p, fault=True)  # the drive tripped just before the command reached it
    assert telegram(take(p)).pcd1 == STOP_WORD


def test_start_after_a_trip_is_needed_and_honoured() -> None:
    p = planner(A)
    adopted(p, running=True, output_pct=50.0)
    answer(p, fault=True)
    p.submit("a", start(), "start")
    answer(p)
    assert telegram(take(p)).pcd1 == RUN_WORD


@pytest.mark.parametrize(
    ("state", "parameter"),
    [
        pytest.param({"fault": True}, ALARM_WORD, id="alarm"),
        pytest.param({"warning": True}, WARNING_WORD, id="warning"),
    ],
)
def test_changed_alarm_or_warning_bit_reads_its_word_with_the_next_poll(
    state: dict[str, Any], parameter: Any
) -> None:
    p = planner(dataclasses.replace(M, monitor=("16-13",)))
    answer(p)
    answer(p, **state)
    assert telegram(take(p)).pnu == parameter.code
    assert telegram(take(p)).pnu == 1613


def test_drive_in_local_operation_leaves_a_start_unconfirmed() -> None:
    p = planner(A)
    adopted(p)
    p.submit("a", start(10.0), "start")
    _, report = answer(p, local=True)
    ((completion,),) = [report.completions]
    assert completion.result.outcome is Outcome.UNCONFIRMED
    assert "local operation" in completion.result.reason


def test_drive_in_local_operation_refuses_a_reference() -> None:
    p = planner(A)
    adopted(p, running=True, output_pct=10.0)
    p.submit("a", set_reference(20.0), "ref")
    _, report = answer(p, local=True, running=True, output_pct=10.0)
    ((completion,),) = [report.completions]
    assert completion.result.outcome is Outcome.REFUSED
    assert "local operation" in completion.result.reason


def test_drive_that_goes_local_while_a_start_waits_leaves_it_unconfirmed() -> None:
    p = planner(A)
    adopted(p)
    p.submit("a", start(10.0), "start")
    assert results(answer(p, 0.0)[1]) == []  # acknowledged, still stopped
    _, report = answer(p, 0.1, local=True)
    assert [(c.tickets, c.result.outcome) for c in report.completions] == [
        (("start",), Outcome.UNCONFIRMED)
    ]
    assert "local operation" in report.completions[0].result.reason


# -- confirmation: done only once the status shows it ------------------------------------


def test_start_is_done_once_the_status_shows_the_drive_running() -> None:
    p = planner(A)
    adopted(p)
    p.submit("a", start(50.0), "start")
    step, report = answer(p, 0.0)  # acknowledged, the drive not running yet
    assert telegram(step).pcd1 == RUN_WORD
    assert results(report) == []
    assert not p.has_commands
    assert p.confirming == 1
    assert results(answer(p, 0.5)[1]) == []
    step, report = answer(p, 1.0, running=True, output_pct=20.0)
    assert telegram(step).pcd1 == RUN_WORD
    assert [(c.tickets, c.result.outcome) for c in report.completions] == [
        (("start",), Outcome.DONE)
    ]


def test_start_ignored_by_the_drive_is_unconfirmed_at_its_deadline() -> None:
    p = planner(dataclasses.replace(A, confirm_s=2.0))
    adopted(p)
    p.submit("a", start(50.0), "start")
    answer(p, 0.0)
    assert results(answer(p, 1.999)[1]) == []
    _, report = answer(p, 2.0)
    ((completion,),) = [report.completions]
    assert completion.result.outcome is Outcome.UNCONFIRMED
    assert completion.result.reason == (
        "not running after 2 s: the drive reports ready but stopped (status word 0x0207)"
    )


def test_a_start_past_its_deadline_is_unconfirmed_even_when_the_exchange_is_a_retried_one() -> None:
    # Every exchange's report ends the confirmations whose deadline has passed, that of a
    # command which failed and will be retried too (its result was one exchange late).
    p = planner(dataclasses.replace(A, confirm_s=2.0), B, retries=1)
    adopted(p)
    p.submit("a", start(50.0), "start")
    answer(p, 0.0)  # acknowledged: now waiting for the status to show it running
    p.submit("b", Command(action=Action.READ, parameter="16-13"), "read")
    step = take(p, 2.5)
    assert step.pending is not None
    assert step.pending.command.action is Action.READ
    report = p.on_failure(step, 2.5, "no reply")
    assert [(c.tickets, c.result.outcome) for c in report.completions] == [
        (("start",), Outcome.UNCONFIRMED)
    ]
    assert p.on_failure(take(p, 2.6), 2.6, "no reply").completions[0].tickets == ("read",)


def test_start_is_unconfirmed_with_the_alarm_text_when_the_drive_trips() -> None:
    p = planner(A)
    adopted(p)
    while p.slot("a").urgent_reads:  # its ramp times, read once it is online
        answer(p)
    p.submit("a", start(50.0), "start")
    answer(p, 0.0)
    assert results(answer(p, 0.1, fault=True)[1]) == []  # which alarm: read next
    step = take(p, 0.2)
    assert telegram(step).pnu == ALARM_WORD.code
    earth_fault = ConditionReport(
        kind="alarm", source="16-90", active=(Condition(code=14, text="Earth fault"),)
    )
    alarm = dataclasses.replace(reply(1, fault=True), conditions=earth_fault)
    (completion,) = p.on_reply(step, alarm, 0.2).completions
    assert completion.result.outcome is Outcome.UNCONFIRMED
    assert completion.result.reason == "the drive is tripped: Earth fault"


def test_stop_is_done_once_the_drive_stands_and_unconfirmed_while_it_still_runs() -> None:
    p = planner(A, dataclasses.replace(B, confirm_s=3.0))
    adopted(p, "b", running=True, output_pct=50.0)
    p.submit("a", STOP, "a-stop")
    p.submit("b", STOP, "b-stop")
    ramping = {1: 40.0, 2: 40.0}  # both acknowledge while still running
    ended: list[tuple[float, Completion]] = []
    now = 0.0
    while len(ended) < 2:
        step = take(p, now)
        assert step.slot is not None
        pct = ramping[step.slot.address]
        answer_ = reply(step.slot.address, running=pct > 0, output_pct=pct)
        ended += [(now, c) for c in p.on_reply(step, answer_, now).completions]
        ramping[1] = 0.0  # a stands after its acknowledgement; b keeps turning
        ramping[2] = 30.0
        now += 0.25
    assert [(at, c.tickets, c.result.outcome) for at, c in ended] == [
        (0.5, ("a-stop",), Outcome.DONE),  # acknowledged at 0, standing at its next poll
        (3.25, ("b-stop",), Outcome.UNCONFIRMED),  # acknowledged at 0.25, deadline 3 s
    ]
    assert ended[1][1].result.reason == (
        "still running at 30.0 % of nominal 3 s after the command (status word 0x0A07)"
    )


def test_a_stop_acknowledged_while_a_start_waits_supersedes_it() -> None:
    p = planner(A)
    adopted(p)
    p.submit("a", start(50.0), "start")
    answer(p, 0.0)
    p.submit("a", Command(action=Action.STOP, actor="ops"), "stop")
    _, report = answer(p, 0.1)
    assert [(c.tickets, c.result.outcome) for c in report.completions] == [
        (("start",), Outcome.SUPERSEDED),
        (("stop",), Outcome.DONE),
    ]
    assert report.completions[0].result.reason == (
        "superseded by stop by ops before its status showed the result"
    )


def test_a_drive_that_stops_answering_leaves_its_start_unconfirmed() -> None:
    p = planner(A, offline_after=2)
    adopted(p)
    p.submit("a", start(50.0), "start")
    answer(p, 0.0)
    assert results(p.on_failure(take(p, 0.1), 0.1, "no reply")) == []
    (completion,) = p.on_failure(take(p, 0.2), 0.2, "no reply").completions
    assert completion.result.outcome is Outcome.UNCONFIRMED
    assert "stopped answering" in completion.result.reason


def test_a_stop_waits_for_the_drives_own_deceleration_time_read_once_online() -> None:
    p = planner(A, B)
    adopted(p, "b", running=True, output_pct=50.0)
    reads = []
    for _ in range(4):  # each drive's acceleration and deceleration times, after adoption
        step = take(p)
        assert step.slot is not None
        pnu = telegram(step).pnu
        reads.append((step.slot.name, pnu))
        raw = {341: 200, 342: 1500}[pnu]  # 2 s and 15 s
        assert step.exchange.parameter is not None
        value = ParameterValue(
            parameter=step.exchange.parameter, index=0, raw=raw, value=raw / 100, unit="s"
        )
        running = step.slot.name == "b"
        p.on_reply(step, reply(step.slot.address, running=running, output_pct=50.0 * running,
                               value=value), 0.0)  # fmt: skip
    assert reads == [("a", 341), ("b", 341), ("a", 342), ("b", 342)]
    assert (p.slot("a").ramp_up_s, p.slot("a").ramp_down_s) == (2.0, 15.0)
    p.submit("b", STOP, "stop")
    answer(p, 1.0, running=True, output_pct=45.0)
    (waiting,) = p.slot("b").confirming
    assert waiting.confirm_s == 17.0  # 15 s from nominal, and a grace of 2 s


def test_references_are_done_on_their_acknowledgement() -> None:
    p = planner(A)
    adopted(p, running=True, output_pct=10.0)
    p.submit("a", set_reference(20.0), "ref")
    _, report = answer(p, 0.0, running=True, output_pct=10.0)  # not at 20 % yet
    assert results(report) == [Outcome.DONE]


def test_parameter_read_ends_done_with_the_value_and_ak_7_ends_refused() -> None:
    p = planner(M)
    p.submit("m", Command(action=Action.READ, parameter="16-13"), "ok")
    p.submit("m", Command(action=Action.READ, parameter="15-00"), "no")
    value = ParameterValue(
        parameter=FcCodec().parameter("16-13"), index=0, raw=503, value=50.3, unit="Hz"
    )
    _, done = answer(p, value=value)
    _, refused = answer(p, error=DriveError(130, "No bus access for this parameter"))
    assert done.completions[0].result == CommandResult(outcome=Outcome.DONE, value=value)
    result = refused.completions[0].result
    assert result.outcome is Outcome.REFUSED
    assert result.error == DriveError(130, "No bus access for this parameter")
    assert "error 130" in result.reason


def test_broadcast_is_sent_to_address_0_and_done_once_sent() -> None:
    p = planner(A, B)
    adopted(p, "b", running=True, output_pct=20.0)
    p.submit(None, STOP, "all")
    step = take(p)
    assert (step.exchange.address, step.exchange.expects_reply) == (0, False)
    assert telegram(step).pcd1 == STOP_WORD
    assert results(p.on_sent(step, 0.0)) == [Outcome.DONE]
    assert {telegram(take(p)).pcd1 for _ in range(2)} == {STOP_WORD}


# -- refusals ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "command", "outcome", "reason"),
    [
        pytest.param("x", STOP, Outcome.INVALID, "no drive called 'x'", id="unknown-drive"),
        pytest.param(
            None, Command(action=Action.READ, parameter="16-13"), Outcome.INVALID,
            "can be broadcast", id="broadcast-read",
        ),
        pytest.param("m", STOP, Outcome.NOT_ALLOWED, "m is monitor-only", id="monitor-only"),
        pytest.param(None, STOP, Outcome.NOT_ALLOWED, "m is monitor-only", id="broadcast"),
        pytest.param(
            "a", start(101.0), Outcome.NOT_ALLOWED, "limit of 50 Hz", id="above-max",
        ),
        pytest.param(
            "a", set_reference(-101.0), Outcome.NOT_ALLOWED, "limit of 50 Hz", id="below-neg-max",
        ),
        pytest.param("b", start(10.0), Outcome.NOT_ALLOWED, "minimum of 10 Hz", id="below-min"),
        pytest.param(
            "a", Command(action=Action.READ, parameter="speed"), Outcome.INVALID,
            "not written like 16-13", id="bad-parameter",
        ),
        pytest.param(
            "a", Command(action=Action.WRITE, parameter="3-41"), Outcome.INVALID,
            "needs a value", id="write-without-value",
        ),
        pytest.param(
            "a", Command(action=Action.WRITE, parameter="3-41", value=math.nan), Outcome.INVALID,
            "", id="write-nan",
        ),
        pytest.param("a", start(math.nan), Outcome.INVALID, "", id="nan-reference"),
        pytest.param("c", start(240.0), Outcome.INVALID, "reference", id="not-encodable"),
    ],
)  # fmt: skip
def test_command_that_cannot_go_on_the_wire_ends_at_once(
    name: str | None, command: Command, outcome: Outcome, reason: str
) -> None:
    p = planner(
        A,
        dataclasses.replace(B, min_frequency_hz=10.0),
        DrivePlan(name="c", address=4, control=True, max_frequency_hz=150.0),
        M,
    )
    ((completion,),) = [p.submit(name, command, "t")]
    assert completion.tickets == ("t",)
    assert completion.result.outcome is outcome
    assert reason in completion.result.reason
    assert not p.has_commands


# -- superseding, coalescing, and commands already on the wire -----------------------------


def test_stop_supersedes_queued_motion_commands_of_that_drive_only() -> None:
    p = planner(A, B)
    adopted(p)
    p.submit("a", start(10.0), "start")
    p.submit("a", Command(action=Action.JOG), "jog")
    p.submit("a", set_reference(20.0), "ref")
    p.submit("a", Command(action=Action.READ, parameter="16-13"), "read")
    p.submit("b", start(10.0), "other")
    ended = p.submit("a", STOP, "stop")
    assert [(c.tickets, c.result.outcome, c.result.reason) for c in ended] == [
        (("start",), Outcome.SUPERSEDED, "superseded by stop"),
        (("jog",), Outcome.SUPERSEDED, "superseded by stop"),
        (("ref",), Outcome.SUPERSEDED, "superseded by stop"),
    ]
    left = []
    while p.has_commands:
        step, _ = answer(p)
        assert step.pending is not None
        left += step.pending.tickets
    assert left == ["stop", "read", "other"]


def test_stop_does_not_cancel_a_start_already_on_the_wire() -> None:
    p = planner(A)
    adopted(p)
    p.submit("a", start(50.0), "start")
    in_flight = take(p)
    assert p.submit("a", STOP, "stop") == []
    assert results(p.on_reply(in_flight, reply(1, running=True, output_pct=50.0), 0.0)) == [
        Outcome.DONE
    ]
    step, report = answer(p, running=True, output_pct=50.0)
    assert telegram(step).pcd1 == STOP_WORD
    assert results(report) == []  # acknowledged; the drive still runs
    assert results(answer(p)[1]) == [Outcome.DONE]


def test_at_shutdown_only_stops_and_the_command_on_the_wire_are_kept() -> None:
    p = planner(A, B)
    adopted(p)
    p.submit("a", start(50.0), "on-wire")
    in_flight = take(p)
    p.submit("b", start(10.0), "start")
    p.submit("a", Command(action=Action.WRITE, parameter="3-41", value=5.0), "write")
    assert p.submit("a", STOP, "stop") == []  # the start of a is on the wire: not superseded
    ended = p.cancel_queued("fcmaster is shutting down")
    assert [(c.tickets, c.result.outcome, c.result.reason) for c in ended] == [
        (("start",), Outcome.CANCELLED, "fcmaster is shutting down"),
        (("write",), Outcome.CANCELLED, "fcmaster is shutting down"),
    ]
    assert results(p.on_reply(in_flight, reply(1, running=True, output_pct=50.0), 0.0)) == [
        Outcome.DONE
    ]
    step, report = answer(p)
    assert (step.slot.name if step.slot else None, telegram(step).pcd1) == ("a", STOP_WORD)
    assert results(report) == [Outcome.DONE]
    assert not p.has_commands


def test_stop_supersedes_a_start_waiting_for_its_retry_so_no_start_follows_the_stop() -> None:
    p = planner(A)
    adopted(p)
    p.submit("a", start(50.0), "start")
    first = take(p)
    assert telegram(first).pcd1 == RUN_WORD
    p.on_failure(first, 0.0, "no reply")
    ((ended,),) = [p.submit("a", Command(action=Action.STOP, actor="ops"), "stop")]
    assert ended.tickets == ("start",)
    assert ended.result.outcome is Outcome.SUPERSEDED
    assert ended.result.reason.startswith("superseded by stop by ops (part of it went out")
    words = []
    for _ in range(4):
        words.append(telegram(answer(p)[0]).pcd1)
    assert words == [STOP_WORD] * 4  # start, stop, and never start again


@pytest.mark.parametrize(
    ("applied", "word", "reference"),
    [
        pytest.param({"running": True, "output_pct": 50.0}, RUN_WORD, 50.0, id="applied"),
        pytest.param({}, STOP_WORD, 0.0, id="not-applied"),
    ],
)
def test_a_timed_out_start_is_followed_by_no_stop_and_the_drive_is_adopted_again(
    applied: dict[str, Any], word: int, reference: float
) -> None:
    p = planner(A)
    adopted(p)
    p.submit("a", start(50.0), "start")
    attempts = []
    for n in range(2):
        step = take(p, float(n))
        assert telegram(step).pcd1 == RUN_WORD
        attempts.append(p.on_failure(step, float(n), "no reply"))
    assert results(*attempts) == [Outcome.TIMEOUT]
    step, _ = answer(p, 2.0, **applied)  # the drive's state, whatever the start did
    assert not telegram(step).pcd1 & ControlWord.DATA_VALID  # commands nothing, no stop
    after = telegram(take(p, 3.0))
    assert (after.pcd1, after.pcd2) == (word, encode_reference(reference))


def test_a_timed_out_stop_is_kept() -> None:
    p = planner(A)
    adopted(p, running=True, output_pct=50.0)
    p.submit("a", STOP, "stop")
    for n in range(2):
        p.on_failure(take(p, float(n)), float(n), "no reply")
    step, _ = answer(p, 2.0, running=True, output_pct=50.0)
    assert telegram(step).pcd1 == STOP_WORD


def test_queued_references_coalesce_and_the_newest_wins() -> None:
    p = planner(A)
    adopted(p, running=True, output_pct=10.0)
    ended = []
    for pct in (20.0, 30.0, 40.0):
        ended += p.submit("a", set_reference(pct), pct)
    assert [(c.tickets, c.result.outcome) for c in ended] == [
        ((20.0,), Outcome.SUPERSEDED),
        ((30.0,), Outcome.SUPERSEDED),
    ]
    step, report = answer(p)
    assert telegram(step).pcd2 == encode_reference(40.0)
    ((completion,),) = [report.completions]
    assert completion.tickets == (40.0,)
    assert not p.has_commands


def test_a_coalesced_reference_ends_superseded_naming_the_newer_one() -> None:
    p = planner(A)
    adopted(p, running=True, output_pct=10.0)
    assert p.submit("a", set_reference(20.0), "first") == []
    newer = Command(action=Action.SET_REFERENCE, reference_pct=30.0, actor="ops")
    ((ended,),) = [p.submit("a", newer, "second")]
    assert (ended.tickets, ended.command.reference_pct) == (("first",), 20.0)
    assert ended.result.outcome is Outcome.SUPERSEDED
    assert ended.result.reason == "superseded by set_reference 30 % by ops"
    step, report = answer(p, running=True, output_pct=30.0)
    assert telegram(step).pcd2 == encode_reference(30.0)
    assert [(c.tickets, c.result.outcome) for c in report.completions] == [
        (("second",), Outcome.DONE)
    ]


def test_reference_does_not_coalesce_into_one_already_on_the_wire() -> None:
    p = planner(A)
    adopted(p, running=True, output_pct=10.0)
    p.submit("a", set_reference(20.0), "first")
    in_flight = take(p)
    p.submit("a", set_reference(30.0), "second")
    assert results(p.on_reply(in_flight, reply(1), 0.0)) == [Outcome.DONE]
    step, report = answer(p)
    assert telegram(step).pcd2 == encode_reference(30.0)
    assert [c.tickets for c in report.completions] == [("second",)]


def test_reference_does_not_coalesce_past_a_later_start_with_a_reference() -> None:
    p = planner(A)
    adopted(p)
    p.submit("a", set_reference(10.0), "ref-10")
    p.submit("a", start(30.0), "start-30")
    p.submit("a", set_reference(20.0), "ref-20")
    while p.has_commands:
        answer(p)
    assert telegram(take(p)).pcd2 == encode_reference(20.0)  # the newest wins


def test_references_of_different_drives_do_not_coalesce() -> None:
    p = planner(A, B)
    p.submit("a", set_reference(10.0), "a")
    p.submit("b", set_reference(20.0), "b")
    ended: list[Outcome] = []
    while p.has_commands:
        ended += results(answer(p)[1])
    assert ended == [Outcome.DONE, Outcome.DONE]


def test_cancel_all_ends_every_queued_command_once() -> None:
    p = planner(A, M)
    adopted(p)
    p.submit("a", STOP, 1)
    p.submit("a", start(10.0), 2)
    p.submit("m", Command(action=Action.READ, parameter="16-13"), 3)
    ended = p.cancel_all("line1 shut down")
    tickets = [t for c in ended for t in c.tickets]
    assert len(tickets) == 3
    assert set(tickets) == {1, 2, 3}
    assert {c.result.reason for c in ended} == {"line1 shut down"}
    assert p.cancel_all("again") == []
    assert not p.has_commands


# -- invariants under random sequences ---------------------------------------------------

DRIVES = (A, DrivePlan(name="b", address=2, control=True, on_start=OnStart.STOP), M)
ANY_NAME = st.sampled_from([None, "a", "b", "m", "nobody"])
NAME = st.sampled_from(["a", "b", "m"])
PERCENT = st.one_of(st.none(), st.floats(-100.0, 100.0), st.floats(-120.0, 120.0))
MOTION = st.sampled_from(
    [Action.START, Action.JOG, Action.SET_REFERENCE, Action.FORWARD, Action.REVERSE]
)
URGENT = st.sampled_from([Action.STOP, Action.COAST, Action.QUICK_STOP])
PROBE_INTERVAL_S = 1.0


def commands() -> st.SearchStrategy[Command]:
    control = st.builds(
        Command,
        action=st.sampled_from([a for a in Action if a.is_control]),
        reference_pct=PERCENT,
    )
    read = st.builds(
        Command, action=st.just(Action.READ), parameter=st.sampled_from(["16-13", "15-40"])
    )
    write = st.builds(
        Command,
        action=st.just(Action.WRITE),
        parameter=st.just("3-41"),
        value=st.one_of(st.none(), st.floats(0.0, 100.0)),
    )
    return st.one_of(control, read, write)


class PlannerMachine(RuleBasedStateMachine):
    """Drives a planner as the master does; commands may arrive while a step is in flight."""

    def __init__(self) -> None:
        super().__init__()
        plan = LinePlan(
            name="line1",
            port="test",
            retries=1,
            offline_after=2,
            probe_interval_s=PROBE_INTERVAL_S,
            drives=DRIVES,
        )
        self.planner = Planner(plan, FcCodec())
        self.now = 0.0
        self.in_flight: Step | None = None
        self.chosen: Step | None = None  # peeked as a reply came in, to go when the pause ends
        self.tickets: list[int] = []
        self.ends: dict[int, list[CommandResult]] = {}
        self.urgent: set[int] = set()  # urgent commands submitted and not ended
        self.last_probe: dict[str, float] = {}
        self.demoted_at: dict[str, float] = {}
        self.polls_since: dict[str, int] = {}
        self.silenced: set[str] = set()  # demoted when the whole line fell silent

    def _ended(self, completions: list[Completion]) -> None:
        for completion in completions:
            for ticket in completion.tickets:
                assert isinstance(ticket, int)
                self.ends.setdefault(ticket, []).append(completion.result)
                self.urgent.discard(ticket)

    def _confirming(self) -> list[Pending]:
        return [pending for slot in self.planner.slots for pending in slot.confirming]

    def _report(self, report: Report) -> None:
        self._ended(report.completions)
        # Every exchange's report ends the confirmations whose deadline has passed.
        assert all(pending.confirm_by > self.now for pending in self._confirming())
        for transition in report.transitions:
            name = transition.drive.name
            if transition.online:
                self.demoted_at.pop(name, None)
                self.polls_since[name] = 0
                self.silenced.discard(name)
            else:
                self.demoted_at[name] = self.now
                self.polls_since.pop(name, None)
                if report.line_silent:
                    self.silenced.add(name)

    def _submit(self, name: str | None, command: Command) -> None:
        ticket = len(self.tickets)
        self.tickets.append(ticket)
        if command.action.is_urgent:
            self.urgent.add(ticket)
        self._ended(self.planner.submit(name, command, ticket))

    @rule(name=NAME, action=MOTION, reference_pct=PERCENT)
    def submit_motion(self, name: str, action: Action, reference_pct: float | None) -> None:
        if action is Action.SET_REFERENCE and reference_pct is None:
            reference_pct = 50.0
        self._submit(name, Command(action=action, reference_pct=reference_pct))

    @rule(name=st.one_of(NAME, st.none()), action=URGENT)
    def submit_urgent(self, name: str | None, action: Action) -> None:
        self._submit(name, Command(action=action))

    @rule(name=ANY_NAME, command=commands())
    def submit_any(self, name: str | None, command: Command) -> None:
        self._submit(name, command)

    def _drive_in_flight(self) -> str | None:
        """The drive whose command is on the wire, if a command is."""
        step = self.in_flight
        if step is None or step.pending is None or step.slot is None:
            return None
        return step.slot.name

    # The race the master lives with: a caller acts on the drive its command is talking to.
    @precondition(lambda self: self._drive_in_flight() is not None)
    @rule(action=URGENT)
    def stop_the_drive_in_flight(self, action: Action) -> None:
        self._submit(self._drive_in_flight(), Command(action=action))

    @precondition(lambda self: self._drive_in_flight() is not None)
    @rule(reference_pct=st.floats(-100.0, 100.0))
    def refer_the_drive_in_flight(self, reference_pct: float) -> None:
        command = Command(action=Action.SET_REFERENCE, reference_pct=reference_pct)
        self._submit(self._drive_in_flight(), command)

    # The master chooses the next step as a reply comes in and sends it when the pause after
    # that reply ends; commands may come in, and the queue be cancelled, in between.
    @precondition(lambda self: self.in_flight is None and self.chosen is None)
    @rule(elapsed=st.floats(0.0, 0.4))
    def choose(self, elapsed: float) -> None:
        self.now += elapsed
        self.chosen = self.planner.peek(self.now)

    @precondition(lambda self: len(self.tickets) % 8 == 3)  # now and then, as line_lost
    @rule()
    def shut_down(self) -> None:
        self._ended(self.planner.cancel_queued("fcmaster is shutting down"))

    @precondition(lambda self: self.in_flight is None)
    @rule(elapsed=st.floats(0.0, 0.4))
    def send(self, elapsed: float) -> None:
        chosen, self.chosen = self.chosen, None
        if chosen is not None and self.planner.still_next(chosen):
            pending = chosen.pending
            assert pending is None or pending.phase is not Phase.ENDED
            assert pending is None or not any(t in self.ends for t in pending.tickets)
            step: Step | None = chosen
            self.planner.commit(chosen, self.now)
        else:
            self.now += elapsed
            step = self.planner.next_step(self.now)
        waiting = {ticket for pending in self._confirming() for ticket in pending.tickets}
        if self.urgent - waiting:  # acknowledged stops wait for their status, not the line
            assert step is not None
            assert step.kind is StepKind.COMMAND
            assert step.pending is not None
            assert step.pending.command.action.is_urgent
        if step is None:
            assert not self.planner.has_commands
            wakeup = self.planner.next_wakeup(self.now)
            assert all(slot.online is False for slot in self.planner.slots)
            assert wakeup is not None
            assert wakeup > self.now
            return
        if step.kind is StepKind.PROBE and step.slot is not None and step.slot.quick_probe:
            assert step.slot.name in self.silenced  # demoted with the whole line
        elif step.kind is StepKind.PROBE:
            assert step.slot is not None
            name = step.slot.name
            assert self.now >= self.demoted_at[name] + PROBE_INTERVAL_S - 1e-9
            assert self.now >= self.last_probe.get(name, -math.inf) + PROBE_INTERVAL_S - 1e-9
            self.last_probe[name] = self.now
        if step.kind is StepKind.POLL:
            assert step.slot is not None
            assert step.slot.online is not False
            if step.slot.online:  # else the attempt of a drive not heard from yet
                for name in self.polls_since:
                    self.polls_since[name] += 1
                self.polls_since[step.slot.name] = 0
                assert max(self.polls_since.values()) < len(DRIVES)
        if not step.exchange.expects_reply:
            self._report(self.planner.on_sent(step, self.now))
            return
        self.in_flight = step

    @precondition(lambda self: self.in_flight is None)
    @rule(elapsed=st.floats(0.0, 1.5))
    def wait(self, elapsed: float) -> None:
        self.now += elapsed

    @precondition(lambda self: self.in_flight is not None)
    @rule(
        running=st.booleans(),
        fault=st.booleans(),
        warning=st.booleans(),
        local=st.booleans(),
        output_pct=st.sampled_from([0.0, 25.0, -50.0]),
        refused=st.booleans(),
    )
    def reply(
        self,
        running: bool,
        fault: bool,
        warning: bool,
        local: bool,
        output_pct: float,
        refused: bool,
    ) -> None:
        step, self.in_flight = self.in_flight, None
        assert step is not None
        error = (
            DriveError(0, "Illegal parameter number")
            if refused and step.exchange.parameter
            else None
        )
        answer = reply(
            step.exchange.address,
            running=running,
            output_pct=output_pct if running else 0.0,
            fault=fault,
            warning=warning,
            local=local,
            error=error,
        )
        self._report(self.planner.on_reply(step, answer, self.now))

    @precondition(lambda self: self.in_flight is not None)
    @rule(elapsed=st.floats(0.0, 0.1))
    def time_out(self, elapsed: float) -> None:
        step, self.in_flight = self.in_flight, None
        assert step is not None
        self.now += elapsed
        self._report(self.planner.on_failure(step, self.now, "no reply"))

    @precondition(lambda self: len(self.tickets) % 8 == 7)  # now and then: it empties the queues
    @rule()
    def line_lost(self) -> None:
        self.in_flight = self.chosen = None  # the step in flight is abandoned with the port
        self._ended(self.planner.cancel_all("line1 lost its port"))

    @invariant()
    def no_command_ends_twice(self) -> None:
        assert all(len(results) == 1 for results in self.ends.values())

    def teardown(self) -> None:
        self._ended(self.planner.cancel_all("line1 shut down"))
        assert sorted(self.ends) == self.tickets
        assert all(len(results) == 1 for results in self.ends.values())


@given(
    events=st.lists(
        st.tuples(st.floats(0.0, 0.6), st.sampled_from([True, True, False])), max_size=300
    )
)
@settings(max_examples=150)
def test_polls_reach_every_drive_and_probes_keep_their_interval(
    events: list[tuple[float, bool]],
) -> None:
    """Random replies and timeouts, no commands: polls stay fair, probes stay slow.

    The round is of the drives that answered: one not heard from yet is tried in the
    probes' share instead.
    """
    p = planner(A, B, M, offline_after=2, probe_interval_s=PROBE_INTERVAL_S)
    now, demoted_at, last_probe = 0.0, dict[str, float](), dict[str, float]()
    polls_since: dict[str, int] = {}
    silenced: set[str] = set()  # demoted when the whole line fell silent
    for elapsed, answered in events:
        now += elapsed
        step = p.next_step(now)
        if step is None:
            assert all(slot.online is False for slot in p.slots)
            wakeup = p.next_wakeup(now)
            assert wakeup is not None
            assert wakeup > now
            now = wakeup
            continue
        assert step.slot is not None
        name = step.slot.name
        if step.kind is StepKind.PROBE and step.slot.quick_probe:
            assert name in silenced  # demoted with the whole line: asked again at once
        elif step.kind is StepKind.PROBE:
            assert now >= demoted_at[name] + PROBE_INTERVAL_S
            assert now >= last_probe.get(name, -math.inf) + PROBE_INTERVAL_S
            last_probe[name] = now
        else:
            assert step.kind is StepKind.POLL
            if step.slot.online:  # else the attempt of a drive not heard from yet
                for other in polls_since:
                    polls_since[other] += 1
                polls_since[name] = 0
                assert max(polls_since.values()) < len(p.slots)  # each polled once a round
        if answered:
            report = p.on_reply(step, reply(step.slot.address), now)
        else:
            report = p.on_failure(step, now, "no reply")
        for transition in report.transitions:
            who = transition.drive.name
            if transition.online:
                polls_since[who] = 0
                silenced.discard(who)
            else:
                demoted_at[who] = now
                polls_since.pop(who, None)
                if report.line_silent:
                    silenced.add(who)


PlannerMachine.TestCase.settings = settings(
    max_examples=150,
    stateful_step_count=40,
    suppress_health_check=[HealthCheck.too_slow],
)
test_planner_invariants_hold_under_random_sequences = PlannerMachine.TestCase


# -- adoption across replies, broadcasts, writes, retracting a poll ----------------------


def test_a_running_drive_is_adopted_only_once_its_output_is_known() -> None:
    # Mitsubishi and ENC read status and output frequency in separate transactions.
    p = planner(DrivePlan(name="a", address=1, control=True, nominal_frequency_hz=50.0))
    step = take(p)
    status_only = Reply(address=1, status=reply(1, running=True).status)
    p.on_reply(step, status_only, 0.0)
    assert p.slot("a").intent is None  # running, at an unknown speed: not adopted yet
    step = take(p)
    assert telegram(step).pcd1 == 0x0000  # so the next poll still does not command it
    p.on_reply(step, Reply(address=1, output_frequency_hz=30.0), 0.0)
    intent = p.slot("a").intent
    assert intent is not None
    assert intent.reference_pct == 60.0  # 30 Hz of a 50 Hz nominal


def test_a_stopped_drive_is_adopted_from_its_status_alone() -> None:
    p = planner(DrivePlan(name="a", address=1, control=True))
    step = take(p)
    p.on_reply(step, Reply(address=1, status=reply(1).status), 0.0)
    assert telegram(take(p)).pcd1 == 0x043C  # a stop word from now on


@pytest.mark.parametrize(
    ("command", "reason"),
    [
        (set_reference(20.0), "only coast, quick_stop, start, stop can be broadcast"),
        (Command(action=Action.RESET), "can be broadcast"),
        (start(), "a broadcast start needs a reference"),
    ],
    ids=["set_reference", "reset", "start-without-reference"],
)
def test_broadcasts_carry_only_whole_states(command: Command, reason: str) -> None:
    p = planner(DrivePlan(name="a", address=1, control=True))
    ((completion,),) = [p.submit(None, command, "t")]
    assert completion.result.outcome is Outcome.INVALID
    assert reason in completion.result.reason


def test_a_broadcast_start_with_a_reference_goes_to_address_0() -> None:
    p = planner(DrivePlan(name="a", address=1, control=True))
    assert p.submit(None, start(40.0), "t") == []
    request = telegram(take(p))
    assert request.address == 0
    assert request.pcd2 == encode_reference(40.0)


def test_parameter_writes_to_a_monitor_only_drive_are_not_allowed() -> None:
    p = planner(DrivePlan(name="m", address=3))
    write = Command(action=Action.WRITE, parameter="3-41", value=5.0)
    ((completion,),) = [p.submit("m", write, "t")]
    assert completion.result.outcome is Outcome.NOT_ALLOWED
    assert "needs control: bus" in completion.result.reason
    read = Command(action=Action.READ, parameter="3-41")
    assert p.submit("m", read, "t") == []  # reading is fine


def test_a_peeked_poll_left_for_a_command_is_chosen_again_after_it() -> None:
    p = planner(DrivePlan(name="a", address=1), DrivePlan(name="b", address=2))
    first = take(p)
    p.on_reply(first, reply(1), 0.0)
    poll = p.peek(0.0)  # b's poll, chosen before the pause
    assert poll is not None
    assert poll.slot is not None
    assert poll.slot.name == "b"
    p.submit("a", Command(action=Action.READ, parameter="16-14"), "t")
    command = take(p)  # peeked again: the command goes first, the poll is not committed
    assert command.kind is StepKind.COMMAND
    p.on_reply(command, reply(1), 0.0)
    again = take(p)
    assert again.kind is StepKind.POLL
    assert again.exchange.request == poll.exchange.request  # same drive, same rotation item


def test_a_peeked_command_cancelled_at_shutdown_is_no_longer_next() -> None:
    p = planner(A, B)
    adopted(p)
    p.submit("b", start(40.0), "start")
    chosen = p.peek(0.0)  # chosen inside the pause after a reply
    assert chosen is not None
    assert chosen.pending is not None
    (ended,) = p.cancel_queued("fcmaster is shutting down")
    assert ended.tickets == ("start",)
    assert not p.still_next(chosen)
    with pytest.raises(ValueError, match="only the step just peeked"):
        p.commit(chosen, 0.0)
    assert not p.has_commands
    assert take(p).kind is StepKind.POLL  # nothing of the start goes out


def test_a_peeked_step_stays_next_when_nothing_came_in_or_ended() -> None:
    p = planner(A, B)
    adopted(p)
    p.submit("a", Command(action=Action.READ, parameter="16-13"), "read")
    p.submit("b", start(40.0), "start")
    chosen = p.peek(0.0)
    assert chosen is not None
    assert chosen.pending is not None
    assert chosen.pending.tickets == ["read"]
    assert p.still_next(chosen)
    p.submit("z", STOP, "no such drive")  # refused: the queue is as it was
    assert p.still_next(chosen)


def test_a_command_that_comes_in_after_a_peek_makes_it_stale() -> None:
    p = planner(A, B)
    adopted(p)
    poll = p.peek(0.0)
    assert poll is not None
    assert poll.kind is StepKind.POLL
    p.submit("b", start(40.0), "start")
    assert not p.still_next(poll)
    chosen = p.peek(0.0)
    assert chosen is not None
    assert chosen.kind is StepKind.COMMAND
    p.submit("a", STOP, "stop")  # a stop goes before the start just chosen
    assert not p.still_next(chosen)
    first = take(p)
    assert (first.slot.name if first.slot else None, telegram(first).pcd1) == ("a", STOP_WORD)


def test_a_newer_reference_replacing_a_peeked_one_is_the_one_built() -> None:
    p = planner(A)
    adopted(p, running=True, output_pct=50.0)
    p.submit("a", set_reference(20.0), "older")
    older = p.peek(0.0)
    assert older is not None
    assert telegram(older).pcd2 == encode_reference(20.0)
    ((replaced,),) = [p.submit("a", set_reference(30.0), "newer")]
    assert replaced.tickets == ("older",)
    assert replaced.result.outcome is Outcome.SUPERSEDED
    step = take(p)
    assert telegram(step).pcd2 == encode_reference(30.0)
    report = p.on_reply(step, reply(1, running=True, output_pct=30.0), 0.0)
    assert [(c.tickets, c.result.outcome) for c in report.completions] == [
        (("newer",), Outcome.DONE)
    ]
    assert telegram(take(p)).pcd2 == encode_reference(30.0)  # the polls carry it on


def test_only_the_step_just_peeked_can_be_committed() -> None:
    p = planner(DrivePlan(name="a", address=1))
    p.submit("a", Command(action=Action.READ, parameter="16-14"), "t")
    with pytest.raises(ValueError, match="only the step just peeked"):
        p.commit(take(p), 0.0)  # already committed
