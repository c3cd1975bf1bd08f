"""Reply deadlines in virtual time: they follow the line once its replies are timed.

The scripted drives answer exactly their delay after the wire time, so the spread of answer
times shrinks to nothing and the deadline to wire time, response delay and a margin of the
answer time once more; a lost reply then costs under two transactions.
"""

from __future__ import annotations

import pytest

from fcmaster.bus.answer_times import ANSWER_SAMPLES
from fcmaster.bus.commands import Outcome
from fcmaster.bus.plan import DrivePlan
from tests.fakes import Sent, Timed
from tests.orders import orders
from tests.unit.bus.bench import DELAY_S, PARAMETER, PAUSE_S, T0, bench, delayed, exchange_s
from tests.unit.bus.fcdrive import FcDrive, FcLine

M = DrivePlan(name="m", address=3)
N = DrivePlan(name="n", address=4)
POLL_S = exchange_s(PARAMETER, PARAMETER) + PAUSE_S  # one answered transaction


def approx(value: float) -> object:
    return pytest.approx(value, abs=1e-9)


def waited(sent: Sent) -> float:
    assert sent.deadline is not None
    return sent.deadline - sent.at


async def test_the_first_replies_wait_the_plans_deadline_then_the_line_is_followed() -> None:
    b = bench(M, N)
    async with b.master:
        await b.clock.run_until(T0 + 2.0)
    plan, sent = b.plan, b.transport.sent
    fixed = plan.reply_timeout(PARAMETER, PARAMETER)
    assert [waited(s) for s in sent[:ANSWER_SAMPLES]] == [approx(fixed)] * ANSWER_SAMPLES
    assert waited(sent[ANSWER_SAMPLES]) < fixed
    # Every answer took exactly DELAY_S: the spread decays and the margin is DELAY_S again.
    assert waited(sent[-1]) == approx(plan.wire_s(2 * PARAMETER) + 2 * DELAY_S)
    assert b.master.stats.timeouts == 0


async def test_a_lost_reply_costs_less_than_two_transactions() -> None:
    drives = [FcDrive(3), FcDrive(4)]
    b = bench(M, N, fc=drives, offline_after=99)
    async with b.master:
        await b.clock.run_until(T0 + 2.0)
        drives[1].silent = True
        lost_at = b.clock.now()
        await b.clock.run_until(lost_at + 0.5)
    sent = b.transport.sent
    lost = next(i for i, s in enumerate(sent) if s.at > lost_at and s.data[2] == 0x80 | 4)
    cost = sent[lost + 1].at - sent[lost].at
    plan = b.plan
    assert cost == approx(
        plan.wire_s(2 * PARAMETER) + 2 * DELAY_S + plan.wire_s(PARAMETER) + plan.gap_s
    )
    assert cost < 2 * POLL_S


async def test_drives_slower_than_configured_are_waited_for_not_timed_out() -> None:
    slow = FcDrive(3)
    b = bench(M, fc=[slow], responder=delayed(FcLine(slow), 3, 0.045), response_delay_s=0.005)
    async with b.master:
        await b.clock.run_until(T0 + 3.0)
    assert b.master.stats.timeouts == 0
    assert b.master.stats.replies > 50
    assert waited(b.transport.sent[-1]) > 0.045  # the answer time measured, plus its spread


async def test_a_configured_timeout_overrides_the_derived_deadline() -> None:
    b = bench(M, timeout_s=0.2)
    async with b.master:
        await b.clock.run_until(T0 + 1.0)
    assert {round(waited(s), 9) for s in b.transport.sent[:-1]} == {0.2}


async def test_a_commands_exchange_keeps_the_plans_deadline() -> None:
    b = bench(M)
    async with b.master:
        await b.clock.run_until(T0 + 1.0)
        count = len(b.transport.sent)
        result = await b.complete(b.submit(orders(b.master, "m").read("16-14")))
        await b.clock.run_for(0.1)
    assert result.outcome is Outcome.DONE
    plan, sent = b.plan, b.transport.sent
    assert waited(sent[count]) == approx(plan.reply_timeout(PARAMETER, PARAMETER))
    assert waited(sent[count + 1]) < waited(sent[count])  # polls go on following the line


async def test_a_reply_that_came_after_its_deadline_widens_the_next_one() -> None:
    drive = FcDrive(3)
    line = FcLine(drive)
    slow = {"left": 0}

    def respond(request: bytes) -> bytes | Timed | None:
        reply = line(request)
        if isinstance(reply, bytes) and slow["left"]:
            slow["left"] -= 1  # a loaded host or an adapter's latency timer: 15 ms more
            return Timed(((exchange_s(PARAMETER, PARAMETER) + 0.015, reply),))
        return reply

    b = bench(M, fc=[drive], responder=respond, offline_after=99)
    async with b.master:
        await b.clock.run_until(T0 + 2.0)
        narrow = b.master._link.deadline_s(PARAMETER, PARAMETER)
        slow["left"] = 2
        await b.clock.run_for(0.5)
    stats = b.master.stats
    assert exchange_s(PARAMETER, PARAMETER) + 0.015 > narrow  # the first slow one misses
    assert (stats.timeouts, stats.late_bytes, stats.crashes) == (1, PARAMETER, 0)
    assert stats.replies > 20  # the second slow one, and those after it, are taken
