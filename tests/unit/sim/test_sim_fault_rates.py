"""Each fault kind happens at its configured rate (seeded, so these runs never vary)."""

from __future__ import annotations

import pytest

from fcmaster.errors import MalformedReply
from fcmaster.protocol.danfoss_fc import decode_telegram
from fcmaster.sim import DriveSettings, FaultPlan, LineSettings, build_line
from tests.fakes import FakeClock
from tests.unit.sim.wire import START, control, drive, fc_line, frames_in, read, transact

N = 2000
RATE = 0.1
TOLERANCE = 0.03  # about five standard deviations of a binomial(2000, 0.1) fraction


def run(plan: FaultPlan, *, spacing_s: float = 0.5) -> tuple[FakeClock, list[bytes]]:
    clock = FakeClock()
    line = fc_line(clock, (1, 2), faults=plan)
    replies = []
    for i in range(N):
        replies.append(transact(line, clock, read(1 + i % 2, 1613)))
        clock.time += spacing_s
    return clock, replies


def test_drop_loses_replies_at_its_rate() -> None:
    _, replies = run(FaultPlan(drop=RATE, seed=1))
    lost = sum(not reply for reply in replies) / N
    assert lost == pytest.approx(RATE, abs=TOLERANCE)


def test_corrupt_breaks_the_check_of_replies_at_its_rate() -> None:
    _, replies = run(FaultPlan(corrupt=RATE, seed=2))
    broken = 0
    for reply in replies:
        assert len(reply) == 16  # corruption changes bytes, never the length
        try:
            decode_telegram(reply, from_drive=True)
        except MalformedReply:
            broken += 1
    assert broken / N == pytest.approx(RATE, abs=TOLERANCE)


def test_late_replies_come_late_s_after_the_normal_time_at_its_rate() -> None:
    clock = FakeClock()
    line = fc_line(clock, (1,), faults=FaultPlan(late=RATE, late_s=0.2, seed=3))
    normal = line.wire_s(32) + 0.010
    late = 0
    for _ in range(N):
        written = clock.now()
        transact(line, clock, read(1, 1613))
        took = clock.now() - written
        assert took == pytest.approx(normal) or took == pytest.approx(normal + 0.2)
        late += took > normal + 0.1
        clock.time += 0.5
    assert late / N == pytest.approx(RATE, abs=TOLERANCE)


def test_noise_bursts_precede_the_reply_at_their_rate() -> None:
    _, replies = run(FaultPlan(noise=RATE, noise_bytes=4, seed=4))
    noisy = 0
    for reply in replies:
        assert frames_in(reply), "noise inside the response delay never hides the reply"
        noisy += len(reply) > 16
        assert len(reply) <= 16 + 4
    assert noisy / N == pytest.approx(RATE, abs=TOLERANCE)


def test_silent_drive_misses_silent_s_and_comes_back_at_its_rate() -> None:
    clock = FakeClock()
    line = fc_line(clock, (1,), faults=FaultPlan(silent=0.02, silent_s=0.25, seed=5))
    answered = []
    for _ in range(N):
        answered.append(bool(transact(line, clock, read(1, 1613))))
        clock.time += 0.1
    onsets = line.counters.silenced
    # Unanswered polls follow each other every 0.1 s (no reply to wait for), so a silence
    # eats the reply that started it and the two polls after it.
    missed = 3
    assert missed * onsets - 2 <= answered.count(False) <= missed * onsets  # the run may end
    assert onsets / (N - (missed - 1) * onsets) == pytest.approx(0.02, abs=0.01)
    assert not any(answered[i : i + missed + 1] == [False] * (missed + 1) for i in range(N))


def test_silent_period_mutes_one_drive_and_its_timeout_acts_meanwhile() -> None:
    clock = FakeClock()
    epoch = clock.now()
    line = build_line(
        LineSettings(),
        [
            (1, DriveSettings(faults=FaultPlan(silent_periods=((1.0, 3.0),)),
                              parameters={"8-03": 0.5, "8-04": 2})),
            (2, DriveSettings()),
        ],
        clock=clock,
    )  # fmt: skip
    seen = []
    while clock.now() < epoch + 4.0:
        seen.append((clock.now() - epoch, bool(transact(line, clock, control(1, START)))))
        assert transact(line, clock, control(2, START))  # the other drive is unaffected
        clock.time += 0.1
    assert all(answered == (not 1.0 <= t < 3.0) for t, answered in seen)
    assert drive(line, 1).control.timed_out is False  # fed again after the silence


def test_same_seed_same_faults() -> None:
    first = run(FaultPlan(drop=RATE, corrupt=RATE, noise=RATE, seed=9))[1]
    second = run(FaultPlan(drop=RATE, corrupt=RATE, noise=RATE, seed=9))[1]
    third = run(FaultPlan(drop=RATE, corrupt=RATE, noise=RATE, seed=10))[1]
    assert first == second != third


def test_per_drive_faults_touch_only_that_drive() -> None:
    clock = FakeClock()
    line = build_line(
        LineSettings(),
        [(1, DriveSettings(faults=FaultPlan(drop=1.0))), (2, DriveSettings())],
        clock=clock,
    )
    assert transact(line, clock, control(1, START)) == b""
    assert frames_in(transact(line, clock, control(2, START)))
