"""Most of a running line losing power at once, in virtual time: who is polled, and when.

110 of 126 drives stop answering together (a cabinet's supply, a feeder). Round-robin alone
polls each of them in its turn until it has missed ``offline_after`` polls, and the 16
drives still on wait behind every miss, three rounds over. With a miss streak the first
pass goes as round-robin's would (every drive not heard since tried once, the one heard
longest ago first, so no drive still on waits longer than it would have), and from then on
the drives still answering are polled between the misses; the silent ones are still given
up after exactly ``offline_after`` misses each.
"""

from __future__ import annotations

import asyncio
import dataclasses
import itertools
from collections.abc import Container
from typing import Any

import pytest

from fcmaster.bus.commands import Outcome
from fcmaster.bus.plan import DrivePlan
from fcmaster.protocol.danfoss_fc import ControlWord, decode_telegram
from tests.orders import orders
from tests.unit.bus.bench import DELAY_S, PARAMETER, PAUSE_S, T0, Bench, bench, exchange_s
from tests.unit.bus.fcdrive import FcDrive

ON = range(1, 17)  # the drives that keep their power
LOST_AT = T0 + 10.0
POLL_S = exchange_s(PARAMETER, PARAMETER) + PAUSE_S  # one answered poll, pause included
END = LOST_AT + 120.0


async def lose_power(lost: Container[int], lost_at: float = LOST_AT, **options: Any) -> Bench:
    """126 drives, all answering, until the drives at ``lost`` lose power at ``lost_at``."""
    fc = [FcDrive(a) for a in range(1, 127)]
    b = bench(*(DrivePlan(name=f"d{a}", address=a) for a in range(1, 127)), fc=fc, **options)
    async with b.master:
        await b.clock.run_until(lost_at)
        assert all(slot.online for slot in b.master.planner.slots)
        for drive in fc:
            drive.silent = drive.address in lost
        await b.clock.run_until(END)
    return b


def longest_wait(b: Bench, on: Container[int], since: float) -> float:
    """The longest a drive of ``on`` went without an answer, counted from ``since`` to END."""
    answered: dict[int, list[float]] = {}
    for sent in b.transport.sent:
        address = decode_telegram(sent.data, from_drive=False).address
        if address in on and sent.at >= since and sent.reply_at is not None:
            answered.setdefault(address, []).append(sent.at)
    return max(y - x for times in answered.values() for x, y in itertools.pairwise([*times, END]))


def miss_s(b: Bench, **options: Any) -> float:
    """Line time one unanswered parameter poll takes: its deadline, then the drain after it.

    The scripted drives answer DELAY_S after the wire time, so the measured deadline is the
    wire time, that delay and the smallest margin (the answer time once more).
    """
    plan = b.plan
    deadline = options.get("timeout_s") or plan.wire_s(2 * PARAMETER) + 2 * DELAY_S
    return deadline + plan.wire_s(PARAMETER) + plan.gap_s


@pytest.mark.parametrize("options", [{}, {"timeout_s": 0.1}], ids=["default", "timeout_0.1"])
async def test_the_drives_still_on_are_polled_between_the_misses_of_the_others(
    options: dict[str, Any],
) -> None:
    lost = range(17, 127)
    b = await lose_power(lost, **options)
    assert_served(b, ON, len(lost), LOST_AT, **options)
    assert not any(not up and int(name[1:]) in ON for name, up, _ in b.observer.availability)
    # The others: each given up after exactly offline_after polls of its own since the loss.
    offline = {name: at for name, up, at in b.observer.availability if not up}
    assert set(offline) == {f"d{a}" for a in lost}
    for address in lost:
        polls = [at for at, _ in b.requests(address) if LOST_AT <= at < offline[f"d{address}"]]
        assert len(polls) == b.plan.offline_after


def assert_served(b: Bench, on: Container[int], silent: int, since: float, **options: Any) -> None:
    """The drives ``on`` never waited longer than one round of misses, and after it less.

    A round: ``silent`` misses and a poll of each drive still on, what round-robin would
    make each of them wait three times over. After the first, each drive still on is polled
    at least once for every miss of as many silent drives as there are drives on, the
    probes of the drives already given up taking their share of the line besides.
    """
    count = sum(1 for a in range(1, 127) if a in on)
    miss = miss_s(b, **options)
    one_round = silent * miss + count * POLL_S
    assert longest_wait(b, on, since - 5.0) <= one_round + 1e-9
    between = count * (POLL_S + miss) / (1.0 - b.plan.probe_share)
    # Counted from one such wait after the first round: a drive found late in it may still
    # be owed its first poll in between when the round ends.
    assert longest_wait(b, on, since + one_round + between) <= between


async def test_a_lone_drive_losing_power_leaves_the_round_as_it_was() -> None:
    b = await lose_power(range(40, 41))
    after = [t.address for at, t in b.requests() if LOST_AT <= at < LOST_AT + 30.0]
    polls = [a for a in after if a != 40]
    # The others keep their round-robin order: each address follows the one before it.
    assert all(y == x % 126 + 1 or (x, y) == (39, 41) for x, y in itertools.pairwise(polls))


@pytest.mark.parametrize("options", [{}, {"timeout_s": 0.1}], ids=["default", "timeout_0.1"])
@pytest.mark.parametrize("after_s", [0.0, 0.9, 1.7], ids=["round_start", "mid", "late"])
async def test_drives_still_on_behind_the_silent_ones_are_served_as_well(
    options: dict[str, Any], after_s: float
) -> None:
    # Still on: 1 and 112-126, behind 110 silent drives; the loss at three points of a round.
    on = {1, *range(112, 127)}
    b = await lose_power(set(range(1, 127)) - on, LOST_AT + after_s, **options)
    assert_served(b, on, 126 - len(on), LOST_AT + after_s, **options)


@pytest.mark.parametrize("options", [{}, {"timeout_s": 0.1}], ids=["default", "timeout_0.1"])
async def test_a_restart_whose_record_names_drives_gone_since_serves_the_others_between(
    options: dict[str, Any],
) -> None:
    # The record of the drives answering names all 126; 110 lost power while the gateway
    # was down. Polled as present, each is given up after its misses, as after a loss.
    fc = [FcDrive(a, silent=a not in ON) for a in range(1, 127)]
    drives = (DrivePlan(name=f"d{a}", address=a) for a in range(1, 127))
    b = bench(*drives, fc=fc, answered_before=frozenset(range(1, 127)), **options)
    async with b.master:
        await b.clock.run_until(END)
    assert_served(b, ON, 110, T0 + 5.0, **options)  # polled from the start, as after a loss
    assert {name for name, up, _ in b.observer.availability if not up} == {
        f"d{a}" for a in range(17, 127)
    }


async def test_a_stop_during_the_streak_goes_out_next_and_is_carried_out() -> None:
    fc = [FcDrive(a) for a in range(1, 127)]
    plans = (DrivePlan(name=f"d{a}", address=a, control=a == 5) for a in range(1, 127))
    b = bench(*plans, fc=fc)
    async with b.master:
        await b.clock.run_until(LOST_AT)
        started = await b.complete(b.submit(orders(b.master, "d5").start(frequency_hz=30)))
        assert started.outcome is Outcome.DONE
        assert fc[4].running
        for drive in fc[16:]:
            drive.silent = True
        await b.clock.run_until(LOST_AT + 8.0)  # the first pass over, misses in between
        asked_at = b.clock.now()
        # The streak is on: silent drives tried, the drives still on polled between.
        recent = {t.address for at, t in b.requests() if at > asked_at - 0.5}
        assert recent & set(ON)
        assert recent - set(ON)
        in_flight = len(b.transport.sent)  # the exchange on the wire now finishes first
        stopped = await b.complete(b.submit(orders(b.master, "d5").stop()))
        assert stopped.outcome is Outcome.DONE
    after = b.transport.sent[in_flight:]
    first = decode_telegram(after[0].data, from_drive=False)
    assert first.address == 5
    assert not first.pcd1 & ControlWord.START
    assert after[0].at - asked_at < 0.2  # at most the exchange in flight before it
    assert not fc[4].running


@pytest.mark.parametrize("after_s", [0.5 * i for i in range(8)])
async def test_wherever_in_the_round_the_power_goes_no_drive_still_on_waits_longer(
    after_s: float,
) -> None:
    # A round of this line takes 3.7 s: the loss at eight points of it. Trying the drives
    # heard most recently first had made some wait 9 s where round-robin made them wait 6.
    lost = range(17, 127)
    b = await lose_power(lost, LOST_AT + after_s)
    assert_served(b, ON, len(lost), LOST_AT + after_s)


async def test_a_reload_during_the_streak_keeps_serving_the_drives_still_on() -> None:
    # SIGHUP while the silent drives are being given up: a drive added, the rest unchanged.
    fc = [FcDrive(a) for a in range(1, 127)]
    b = bench(*(DrivePlan(name=f"d{a}", address=a) for a in range(1, 126)), fc=fc)
    lost = range(17, 127)
    async with b.master:
        await b.clock.run_until(LOST_AT)
        for drive in fc[16:]:
            drive.silent = True
        await b.clock.run_until(LOST_AT + 8.0)  # the first round over, misses in between
        plan = dataclasses.replace(
            b.plan, drives=(*b.plan.drives, DrivePlan(name="d126", address=126))
        )
        await b.complete(asyncio.ensure_future(b.master.reconfigure(plan)))
        reloaded_at = b.clock.now()
        await b.clock.run_until(END)
    miss = miss_s(b)
    between = len(ON) * (POLL_S + miss) / (1.0 - b.plan.probe_share)
    # Not a second first round: the streak goes on over the reload.
    assert longest_wait(b, ON, reloaded_at - between) <= between
    offline = {name: at for name, up, at in b.observer.availability if not up}
    assert set(offline) == {f"d{a}" for a in lost}
