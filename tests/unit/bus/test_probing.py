"""Absent drives and a silent line, in virtual time: what the wire carries, and when.

Probes of absent drives keep to their share of the line, one at a time, so the drives that
answer keep their poll rate; a line that falls silent as a whole is asked again at once and
every drive is back within about one round when it answers.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import Any

import pytest

from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.protocol.danfoss_fc import decode_telegram
from fcmaster.subcommands.daemon import longest_probe_wait_s
from tests.unit.bus.bench import (
    DELAY_S,
    PARAMETER,
    PAUSE_S,
    PROCESS,
    T0,
    Bench,
    bench,
    exchange_s,
)
from tests.unit.bus.fcdrive import FcDrive

POLL_S = exchange_s(PARAMETER, PARAMETER) + PAUSE_S  # one answered poll, pause included
PRESENT = 16


def approx(value: float) -> object:
    return pytest.approx(value, abs=1e-9)


def fleet(configured: int, present: int, probe_interval_s: float = 5.0, **options: Any) -> Bench:
    drives = [DrivePlan(name=f"d{a}", address=a) for a in range(1, configured + 1)]
    fc = [FcDrive(a, silent=a > present) for a in range(1, configured + 1)]
    return bench(*drives, fc=fc, probe_interval_s=probe_interval_s, **options)


def probe_cost(b: Bench) -> float:
    """Line time an unanswered probe takes: its deadline, then the drain for a late reply.

    The scripted drives all answer exactly DELAY_S after the wire time, so once the line
    has timed its replies the deadline is the wire time, that delay and the smallest margin
    (the answer time once more).
    """
    plan = b.plan
    deadline = plan.wire_s(2 * PROCESS) + 2 * DELAY_S
    return deadline + plan.wire_s(PROCESS) + plan.gap_s


async def test_absent_drives_are_probed_within_their_share_and_live_ones_keep_their_rate() -> None:
    b = fleet(126, PRESENT, probe_share=0.1)
    async with b.master:
        await b.clock.run_until(T0 + 60.0)  # every absent drive demoted by now
        assert all(s.online is (s.address <= PRESENT) for s in b.master.planner.slots)
        start = b.clock.now()
        await b.clock.run_until(start + 120.0)
    requests = [(at, t.address) for at, t in b.requests() if at >= start]
    period = PRESENT * POLL_S  # each live drive's poll period with no absent drive configured
    cost = probe_cost(b)
    probes = [(at, a) for at, a in requests if a > PRESENT]
    # Evenly spread: start to start, each probe is followed by nine times its cost of polls.
    for (before, _), (after, _) in itertools.pairwise(probes):
        assert after - before >= cost / 0.1 - 1e-9
        assert after - before <= cost / 0.1 + POLL_S + 1e-9
    # Every absent drive is still probed regularly.
    assert {a for _, a in probes} == set(range(PRESENT + 1, 127))
    for address in range(PRESENT + 1, 127):
        times = [at for at, a in probes if a == address]
        assert all(b2 - b1 <= 110 * (cost / 0.1 + POLL_S) for b1, b2 in itertools.pairwise(times))
    for address in range(1, PRESENT + 1):
        times = [at for at, a in requests if a == address]
        gaps = [after - before for before, after in itertools.pairwise(times)]
        # Exact spacing: a round of polls, plus a probe's cost for each that came in between
        # (probes go every ten probe costs, so a round holds one or two of them here).
        for gap in gaps:
            probes_between = round((gap - period) / cost)
            assert gap == approx(period + probes_between * cost)
            assert probes_between <= math.ceil(period / (cost / 0.1))
        assert max(gaps) <= 3 * period
        rate = (len(times) - 1) / (times[-1] - times[0])
        assert rate >= 0.9 / period


async def test_a_silent_line_is_a_line_fault_and_every_drive_is_back_within_a_round() -> None:
    b = fleet(8, 8, probe_interval_s=5.0)
    async with b.master:
        await b.clock.run_until(T0 + 1.0)
        assert all(s.online for s in b.master.planner.slots)
        for drive in b.drives.values():
            drive.silent = True  # the cable is pulled
        silent_at = b.clock.now()
        await b.clock.run_until(silent_at + 10.0)
        planner = b.master.planner
        assert planner.line_silent
        assert b.master.stats.to_json(b.clock.now())["line_silent"] is True
        assert all(s.online is False for s in planner.slots)
        # Asked one after the other, not at the 5 s probe interval.
        quiet = [at for at, _ in b.requests() if at > silent_at + 2.0]
        assert len(quiet) > 50
        for drive in b.drives.values():
            drive.silent = False  # plugged back in
        back_at = b.clock.now()
        await b.clock.run_until(back_at + 1.0)
        assert not planner.line_silent
        assert b.master.stats.to_json(b.clock.now())["line_silent"] is False
    offline = [(n, at) for n, online, at in b.observer.availability if not online]
    assert sorted(n for n, _ in offline) == sorted(f"d{a}" for a in range(1, 9))
    returned = [at for _, online, at in b.observer.availability if online and at > back_at]
    assert len(returned) == 8
    # Within about one round: the first answer ends the fault, the rest are asked at once.
    longest_wait = probe_cost(b)  # the probe under way when the line came back
    assert max(returned) - back_at <= longest_wait + 8 * (exchange_s(PROCESS, PROCESS) + PAUSE_S)


async def test_one_absent_drive_among_answering_ones_is_no_line_fault() -> None:
    b = fleet(4, 4, probe_interval_s=1.0)
    async with b.master:
        await b.clock.run_until(T0 + 0.5)
        b.drives[3].silent = True
        await b.clock.run_until(T0 + 5.0)
        assert not b.master.planner.line_silent
    assert [(n, online) for n, online, _ in b.observer.availability[4:]] == [("d3", False)]
    probes = [at for at, t in b.requests(3) if at > T0 + 1.0 and t.pke is None]
    assert all(after - before >= 1.0 for before, after in itertools.pairwise(probes))


def test_the_check_reports_the_longest_wait_for_a_probe_growing_with_the_absent() -> None:
    drives = tuple(DrivePlan(name=f"d{a}", address=a) for a in range(1, 127))
    plan = LinePlan(name="line1", port="x", drives=drives, baudrate=115200, probe_share=0.1)
    # An FC probe is 8 bytes each way; unanswered it costs its deadline and the drain.
    char_s = 11 / 115200
    cost = 16 * char_s + 0.010 + 0.050 + 8 * char_s + max(3.5 * char_s, 0.002)
    assert longest_probe_wait_s(plan) == pytest.approx(125 * cost / 0.1)
    few = dataclasses.replace(plan, drives=drives[:3])
    assert longest_probe_wait_s(few) == 5.0  # the probe interval, when few are absent


async def test_a_line_silent_after_its_port_came_back_is_a_line_fault_too() -> None:
    b = fleet(4, 4)
    async with b.master:
        await b.clock.run_until(T0 + 0.5)
        in_flight = await b.mid_transaction()
        b.transport.lost = True
        for drive in b.drives.values():
            drive.silent = True  # the adapter is back, the drives' power is not
        await b.clock.run_until((in_flight.reply_at or 0.0) + 3.0)
        assert b.master.is_up
        assert b.master.planner.line_silent
        assert all(s.quick_probe for s in b.master.planner.slots)
        for drive in b.drives.values():
            drive.silent = False
        back_at = b.clock.now()
        await b.clock.run_for(0.5)
    returned = [at for _, online, at in b.observer.availability if online and at > back_at]
    assert len(returned) == 4
    assert max(returned) - back_at <= probe_cost(b) + 4 * (exchange_s(PROCESS, PROCESS) + PAUSE_S)


def answered_polls(b: Bench, start: float, end: float) -> dict[int, list[float]]:
    """When each drive's requests in [start, end) went out, for those that were answered."""
    answered = {(name, at) for name, _, at, _ in b.observer.replies}
    sent = b.transport.sent
    times: dict[int, list[float]] = {}
    for request in sent:
        address = decode_telegram(request.data, from_drive=False).address
        if start <= request.at < end and (f"d{address}", request.reply_at) in answered:
            times.setdefault(address, []).append(request.at)
    return times


async def all_alive_interval(options: dict[str, Any], span: float = 20.0) -> float:
    """A present drive's poll interval with only the present drives configured."""
    alone = fleet(PRESENT, PRESENT, **options)
    async with alone.master:
        await alone.clock.run_until(T0 + span)
    full = answered_polls(alone, T0, T0 + span)
    return span * PRESENT / sum(len(t) for t in full.values())


async def test_from_start_absent_drives_are_tried_in_the_probe_share_not_polled_as_present() -> (
    None
):
    """126 configured, 16 present, a user's timeouts: the present keep their rate from start.

    Each drive not heard from gets one poll, in the probes' share of the line, then waits
    for its probe; it is not polled as if present until ``offline_after`` misses.
    """
    options = {"baudrate": 115200, "timeout_s": 0.1, "retries": 1}
    span = 20.0
    alone = fleet(PRESENT, PRESENT, **options)  # the same drives, none absent
    async with alone.master:
        await alone.clock.run_until(T0 + span)
    full = answered_polls(alone, T0, T0 + span)
    period = span * PRESENT / sum(len(t) for t in full.values())  # a drive's poll interval
    bound = max(0.5, 3 * period)
    b = fleet(126, PRESENT, **options)
    async with b.master:
        await b.clock.run_until(T0 + span)
    polled = answered_polls(b, T0, T0 + span)
    assert set(polled) == set(range(1, PRESENT + 1))
    for address in range(1, PRESENT + 1):
        times = [T0, *polled[address], T0 + span]
        longest = max(after - before for before, after in itertools.pairwise(times))
        assert longest <= bound, (address, longest, bound)
    # From the first second, the present drives' answered polls: at least 0.9 of all-alive.
    assert sum(len(t) for t in polled.values()) >= 0.9 * sum(len(t) for t in full.values())
    # Every absent drive had its one poll, and was demoted after it.
    tried = [t.address for _, t in b.requests() if t.address > PRESENT and t.pke is not None]
    assert sorted(tried) == list(range(PRESENT + 1, PRESENT + 1 + len(tried)))
    assert len(tried) >= 15
    assert all(s.online is not True for s in b.master.planner.slots[PRESENT:])


async def test_absent_drives_powering_up_one_by_one_are_found_within_the_probes_time() -> None:
    options = {"baudrate": 115200, "timeout_s": 0.1, "retries": 1}
    b = fleet(126, PRESENT, **options)
    wait = longest_probe_wait_s(b.plan)  # the longest an absent drive waits for its probe
    powered = {20: T0 + 30.0, 60: T0 + 10.0, 126: T0 + 50.0}  # 20 demoted, 60 not yet tried
    async with b.master:
        for address, at in sorted(powered.items(), key=lambda item: item[1]):
            await b.clock.run_until(at)
            b.drives[address].silent = False
        await b.clock.run_until(max(powered.values()) + wait + 1.0)
    online = {name: at for name, up, at in b.observer.availability if up}
    for address, at in powered.items():
        found = online[f"d{address}"] - at
        assert 0 < found <= wait + probe_cost(b), (address, found, wait)


async def test_after_a_reopen_the_drives_not_heard_yet_still_wait_for_the_probes_share() -> None:
    options = {"baudrate": 115200, "timeout_s": 0.1, "retries": 1}
    b = fleet(126, PRESENT, **options)
    async with b.master:
        await b.clock.run_until(T0 + 5.0)  # most absent drives not tried yet
        untried = sum(s.online is None for s in b.master.planner.slots)
        assert untried > 90
        b.transport.lost = True  # the adapter is unplugged and plugged back in
        await b.clock.run_until(T0 + 25.0)
        assert b.master.is_up
    assert [up for up, _, _ in b.observer.lines] == [True, False, True]
    back = b.observer.lines[2][2]
    polled = answered_polls(b, back, T0 + 25.0)
    bound = max(0.5, 3 * await all_alive_interval(options))
    for address in range(1, PRESENT + 1):
        times = [back, *polled[address], T0 + 25.0]
        longest = max(after - before for before, after in itertools.pairwise(times))
        assert longest <= bound, (address, longest)


# A restart with the low addresses unpowered: the drives that answer sit behind 109 absent ones.
AFTER_ABSENT = frozenset({1, *range(111, 127)})


def spread_fleet(present: frozenset[int], **options: Any) -> Bench:
    drives = [DrivePlan(name=f"d{a}", address=a) for a in range(1, 127)]
    fc = [FcDrive(a, silent=a not in present) for a in range(1, 127)]
    return bench(*drives, fc=fc, probe_interval_s=5.0, **options)


async def test_without_a_record_the_drives_behind_the_absent_ones_wait_for_their_one_attempt() -> (
    None
):
    """Why the record exists: untried drives are tried in the probes' share, in line order."""
    options = {"baudrate": 115200, "timeout_s": 0.1, "retries": 1}
    b = spread_fleet(AFTER_ABSENT, **options)
    async with b.master:
        await b.clock.run_until(T0 + 60.0)
    polled = answered_polls(b, T0, T0 + 60.0)
    assert set(polled) == {1}  # a minute on, 111–126 have not had a poll answered


async def test_a_restart_polls_at_once_the_drives_that_answered_before_wherever_they_sit() -> None:
    """The record of the last run: 111–126 polled as present from the start, absent ones tried.

    From the start, every drive that answered before keeps its all-alive rate and none goes
    longer than max(0.5 s, 3 poll intervals) without an answer, while the absent drives still
    get their one attempt each in the probes' share.
    """
    options: dict[str, Any] = {"baudrate": 115200, "timeout_s": 0.1, "retries": 1}
    span = 20.0
    alone = bench(*[DrivePlan(name=f"d{a}", address=a) for a in sorted(AFTER_ABSENT)], **options)
    async with alone.master:
        await alone.clock.run_until(T0 + span)
    full = answered_polls(alone, T0, T0 + span)
    period = span * len(AFTER_ABSENT) / sum(len(t) for t in full.values())
    bound = max(0.5, 3 * period)
    b = spread_fleet(AFTER_ABSENT, answered_before=AFTER_ABSENT, **options)
    async with b.master:
        await b.clock.run_until(T0 + span)
    polled = answered_polls(b, T0, T0 + span)
    assert set(polled) == set(AFTER_ABSENT)
    for address in AFTER_ABSENT:
        times = [T0, *polled[address], T0 + span]
        longest = max(after - before for before, after in itertools.pairwise(times))
        assert longest <= bound, (address, longest, bound)
    # From the 3rd second, as at any start: at least 0.9 of the all-alive rate.
    late, alive = answered_polls(b, T0 + 3.0, T0 + span), answered_polls(alone, T0 + 3.0, T0 + span)
    assert sum(map(len, late.values())) >= 0.9 * sum(map(len, alive.values()))
    tried = [t.address for _, t in b.requests() if t.address not in AFTER_ABSENT]
    assert tried[:15] == list(range(2, 17))  # the absent ones, one attempt each, in order
    assert len(tried) == len(set(tried))


async def test_a_drive_that_answered_before_and_is_gone_now_is_given_up_after_its_misses() -> None:
    """The record is a guess: a drive it names that no longer answers is demoted as any other."""
    options = {"baudrate": 115200, "timeout_s": 0.1, "retries": 1}
    gone = 111
    b = spread_fleet(AFTER_ABSENT - {gone}, answered_before=AFTER_ABSENT, **options)
    async with b.master:
        await b.clock.run_until(T0 + 5.0)
        slot = next(s for s in b.master.planner.slots if s.address == gone)
        assert slot.online is False
    asked = [at for at, t in b.requests() if t.address == gone]
    assert len(asked) == b.plan.offline_after  # polled as present until its misses, then demoted
    polled = answered_polls(b, T0, T0 + 5.0)
    assert set(polled) == AFTER_ABSENT - {gone}
