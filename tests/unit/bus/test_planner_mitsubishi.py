"""The planner with the Mitsubishi codec: commands of several exchanges, and the reset.

A Mitsubishi parameter takes two transactions (the page HFF, then the access), and the
inverter reset gets no reply and leaves the drive deaf while it restarts. Replies are the
codec's own parse of frames built with the encoder, so these tests also pin the bytes the
planner puts on the wire.
"""

from __future__ import annotations

import pytest

from fcmaster.bus.commands import Action, Command, Outcome
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.bus.planner import Planner, Report, Step, StepKind
from fcmaster.protocol.codec import Reply
from fcmaster.protocol.drive import Motion
from fcmaster.protocol.mitsubishi import (
    RESTART_S,
    Ack,
    DataReply,
    MitsubishiCodec,
    Nak,
    Terminator,
    encode_frame,
)

A = DrivePlan(name="a", address=1, control=True)
B = DrivePlan(name="b", address=2, control=True)
PAGE_0 = b"\x0501FF0007D\r"  # FF 00, digit 0: 48+49+70+70+48+48+48 = 381 = 0x17D
READ_PR7 = b"\x0501070F8\r"  # 07 read: 48+49+48+55+48 = 248 = 0xF8
WRITE_PR7_25 = b"\x05018700019CA\r"  # 87, 0019 (2.5 s): 453 - 51 - 50 + 49 + 57 = 458
RESET = b"\x0501FD09696F9\r"


def planner(*drives: DrivePlan, retries: int = 1) -> Planner:
    plan = LinePlan(name="line1", port="test", protocol="mitsubishi", retries=retries,
                    drives=drives)  # fmt: skip
    return Planner(plan, MitsubishiCodec())


def take(p: Planner, now: float = 0.0) -> Step:
    step = p.next_step(now)
    assert step is not None
    return step


def answer(p: Planner, step: Step, frame: bytes, now: float = 0.0) -> Report:
    """``frame`` (a drive's reply) as the codec reads it, reported to the planner."""
    return p.on_reply(step, p.codec.parse(step.exchange, frame), now)


def ack(address: int) -> bytes:
    return encode_frame(Ack(address), Terminator.CR)


def data(address: int, value: int, width: int = 4) -> bytes:
    return encode_frame(DataReply(station=address, data=value, width=width), Terminator.CR)


def status(p: Planner, address: int, word: int, now: float = 0.0) -> Step:
    """Serve polls until one reads the status of ``address``; answer it with ``word``."""
    while True:
        step = take(p, now)
        assert step.kind is StepKind.POLL
        if step.exchange.request[3:5] == b"7A" and step.exchange.address == address:
            answer(p, step, data(address, word, 2), now)
            return step
        reply = data(step.exchange.address, 0)
        p.on_reply(step, p.codec.parse(step.exchange, reply), now)


def test_parameter_read_sets_the_page_then_reads_and_ends_with_the_value() -> None:
    p = planner(A)
    assert p.submit("a", Command(action=Action.READ, parameter="Pr.7"), "t") == []
    page = take(p)
    assert (page.kind, page.exchange.request) == (StepKind.COMMAND, PAGE_0)
    assert answer(p, page, ack(1)).completions == []  # not done: the read is next
    read = take(p)
    assert read.pending is page.pending
    assert read.exchange.request == READ_PR7
    (done,) = answer(p, read, data(1, 50)).completions
    assert done.result.outcome is Outcome.DONE
    assert done.tickets == ("t",)
    assert done.result.value is not None
    assert (done.result.value.value, done.result.value.unit) == (5.0, "s")
    assert take(p).kind is StepKind.POLL  # the command is gone


def test_parameter_write_sends_page_and_value_and_confirms_it() -> None:
    p = planner(A)
    p.submit("a", Command(action=Action.WRITE, parameter="Pr.7", value=2.5), "t")
    page = take(p)
    assert page.exchange.request == PAGE_0
    answer(p, page, ack(1))
    write = take(p)
    assert write.exchange.request == WRITE_PR7_25
    (done,) = answer(p, write, ack(1)).completions
    assert done.result.outcome is Outcome.DONE
    assert done.result.value is not None
    assert done.result.value.value == 2.5


@pytest.mark.parametrize("refused_part", [0, 1])
def test_a_refusal_of_either_exchange_ends_the_command_with_that_refusal(
    refused_part: int,
) -> None:
    p = planner(A)
    p.submit("a", Command(action=Action.WRITE, parameter="Pr.7", value=2.5), "t")
    if refused_part:
        answer(p, take(p), ack(1))
    step = take(p)
    report = answer(p, step, encode_frame(Nak(1, 0xA), Terminator.CR))
    (done,) = report.completions
    assert done.result.outcome is Outcome.REFUSED
    assert done.result.error is not None
    assert done.result.error.code == 0xA
    assert "Mode error" in done.result.reason
    assert take(p).kind is StepKind.POLL  # nothing more of it goes on the wire


def test_a_parameter_access_that_times_out_part_way_starts_again_from_the_page() -> None:
    p = planner(A, retries=1)
    p.submit("a", Command(action=Action.READ, parameter="Pr.7"), "t")
    answer(p, take(p), ack(1))
    read = take(p)
    assert read.exchange.request == READ_PR7
    assert p.on_failure(read, 0.1, "no reply").completions == []
    again = take(p, 0.2)
    assert again.exchange.request == PAGE_0  # the page may be gone: set it again
    answer(p, again, ack(1), 0.2)
    read = take(p, 0.3)
    assert p.on_failure(read, 0.4, "no reply").completions[0].result.outcome is Outcome.TIMEOUT


def test_reset_expects_no_reply_ends_once_and_leaves_the_drive_stopped() -> None:
    p = planner(A)
    status(p, 1, 0x4B)  # running forward at frequency: adopted as running
    frequency = take(p)
    assert frequency.exchange.request[3:5] == b"6F"
    answer(p, frequency, data(1, 2500))  # 25 Hz: now the running drive can be adopted
    adopted = p.slot("a").intent
    assert adopted is not None
    assert adopted.motion is Motion.RUN
    p.submit("a", Command(action=Action.RESET), "reset")
    step = take(p, 1.0)
    assert step.exchange.request == RESET
    assert not step.exchange.expects_reply
    (done,) = p.on_sent(step, 1.0).completions
    assert (done.tickets, done.result.outcome) == (("reset",), Outcome.DONE)
    intent = p.slot("a").intent
    assert intent is not None
    assert (intent.motion, intent.reset) == (Motion.STOP, False)  # never restarts the motor


def test_a_reset_drive_is_left_alone_for_its_restart_while_others_are_served() -> None:
    p = planner(A, B)
    status(p, 1, 0x00)
    status(p, 2, 0x00)
    p.submit("a", Command(action=Action.RESET), "reset")
    sent_at = 10.0
    p.on_sent(take(p, sent_at), sent_at)
    # During the restart: only drive b is polled, and a command for a waits behind b's.
    p.submit("a", Command(action=Action.READ, parameter="H6F"), "read-a")
    p.submit("b", Command(action=Action.READ, parameter="H6F"), "read-b")
    during = sent_at + RESTART_S / 2
    step = take(p, during)
    assert step.pending is not None
    assert step.pending.tickets == ["read-b"]
    answer(p, step, data(2, 0), during)
    for _ in range(4):
        step = take(p, during)
        assert step.exchange.address == 2
        answer(p, step, data(2, 0, 4 if step.exchange.request[3:5] != b"7A" else 2), during)
    # One drive alone and deaf: nothing to do until it is back.
    lone = planner(A)
    status(lone, 1, 0x00)
    lone.submit("a", Command(action=Action.RESET), "reset")
    lone.on_sent(take(lone, sent_at), sent_at)
    assert lone.next_step(during) is None
    assert lone.next_wakeup(during) == pytest.approx(sent_at + RESTART_S)
    # After it: the queued command for a goes first, then a is polled again.
    after = sent_at + RESTART_S
    step = take(p, after)
    assert step.pending is not None
    assert step.pending.tickets == ["read-a"]
    answer(p, step, data(1, 0), after)
    addresses = {take_and_answer(p, after) for _ in range(4)}
    assert addresses == {1, 2}


def take_and_answer(p: Planner, now: float) -> int:
    step = take(p, now)
    width = 2 if step.exchange.request[3:5] == b"7A" else 4
    reply: Reply = p.codec.parse(step.exchange, data(step.exchange.address, 0, width))
    p.on_reply(step, reply, now)
    return step.exchange.address


def test_a_relative_command_learns_status_then_output_before_it_commands() -> None:
    # H7A alone does not tell the output, so one status poll can never adopt a running
    # drive: the learning polls go on to H6F, then the command keeps that output.
    p = planner(A)
    p.submit("a", Command(action=Action.REVERSE), "t")
    learn = take(p)
    assert learn.exchange.request == b"\x05017A009\r"
    assert answer(p, learn, data(1, 0x4B, 2)).completions == []  # running forward
    learn = take(p)
    assert learn.exchange.request == b"\x05016F00D\r"
    answer(p, learn, data(1, 2000))  # 20 Hz of 50: adopted at 40 %
    frequency = take(p)
    assert frequency.exchange.request[3:10] == b"ED007D0"  # 20.00 Hz kept
    answer(p, frequency, ack(1))
    run = take(p)
    assert run.exchange.request[3:8] == b"FA004"  # STR (after the waiting digit 0)
    (done,) = answer(p, run, ack(1)).completions
    assert done.result.outcome is Outcome.DONE


def test_learning_gives_up_after_a_whole_rotation_without_the_output() -> None:
    p = planner(DrivePlan(name="a", address=1, control=True, monitor=("H70",)))
    p.submit("a", Command(action=Action.SET_REFERENCE, reference_pct=10.0), "t")
    ends: list[Outcome] = []
    for _ in range(4):
        step = take(p)
        assert step.kind is StepKind.COMMAND
        width = 2 if step.exchange.request[3:5] == b"7A" else 4
        ends += [
            c.result.outcome
            for c in answer(p, step, data(1, 0x4B if width == 2 else 900, width)).completions
        ]
        if ends:
            break
    assert ends == [Outcome.TIMEOUT]
