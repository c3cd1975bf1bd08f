"""Commands share the line with the round: a flood of them never leaves the other drives
unpolled, and a plant's command, or a stop, is never made to wait for a poll.

In virtual time on a scripted FC line of eight drives: two callers each send one reference
after another to drive 1, as fast as their outcomes come back (two SCADA screens, a script
in a loop). Before, no other drive was polled for as long as they kept on.
"""

from __future__ import annotations

import asyncio
import itertools

from fcmaster.bus.commands import Outcome
from fcmaster.bus.plan import DrivePlan
from fcmaster.bus.share import BURST_S
from tests.orders import orders
from tests.unit.bus.bench import RUN_WORD, STOP_WORD, T0, Bench, bench

DRIVES = [DrivePlan(name=f"d{a}", address=a, control=True) for a in range(1, 9)]
FLOOD_S = 3.0


async def _flood(b: Bench, until: float) -> int:
    """One caller sending references to d1 one after another until ``until``; how many."""
    drive, sent = orders(b.master, "d1"), 0
    while b.clock.now() < until:
        result = await drive.set_reference(frequency_hz=10 + sent % 20)
        assert result.outcome in (Outcome.DONE, Outcome.SUPERSEDED), result
        sent += 1
    return sent


def _gaps(b: Bench, address: int, since: float, until: float) -> list[float]:
    """The times between polls of drive ``address`` from ``since`` to ``until``."""
    times = [since, *(at for at, _ in b.requests(address) if since <= at < until), until]
    return [later - earlier for earlier, later in itertools.pairwise(times)]


async def test_two_callers_flooding_one_drive_leave_every_other_drive_polled() -> None:
    b = bench(*DRIVES)
    async with b.master:
        await b.clock.run_until(T0 + 1.0)  # every drive adopted
        assert (await b.complete(b.submit(orders(b.master, "d1").start(frequency_hz=10)))).ok
        round_s = max(_gaps(b, 2, T0 + 0.5, b.clock.now()))  # a round without commands
        start = b.clock.now()
        flood = [asyncio.ensure_future(_flood(b, start + FLOOD_S)) for _ in range(2)]
        counts = await b.complete(asyncio.gather(*flood), within=FLOOD_S + 5)
    assert sum(counts) > 2 * FLOOD_S / 0.1  # the commands still had most of the line
    for address in range(2, 9):
        gaps = _gaps(b, address, start, start + FLOOD_S)
        # Alternating with the commands, a round takes at most twice its time, plus the
        # burst the commands had before they started taking turns.
        assert max(gaps) <= 2 * round_s + BURST_S + 0.05, (address, max(gaps), round_s)


async def test_a_stop_in_a_flood_goes_next_and_a_lone_command_is_never_interrupted() -> None:
    b = bench(*DRIVES)
    async with b.master:
        await b.clock.run_until(T0 + 1.0)
        d1, d2 = orders(b.master, "d1"), orders(b.master, "d2")
        assert (await b.complete(b.submit(d1.start(frequency_hz=10)))).ok
        start = b.clock.now()
        flood = [asyncio.ensure_future(_flood(b, start + 1.5)) for _ in range(2)]
        await b.clock.run_until(start + 1.0)  # the commands take turns with polls by now
        stop = b.submit(d2.stop())
        stop_at = b.clock.now()
        result = await b.complete(stop)
        await b.complete(asyncio.gather(*flood), within=5)
    assert result.outcome is Outcome.DONE
    (first_stop,) = [at for at, t in b.requests(2) if at >= stop_at and t.pcd1 == STOP_WORD][:1]
    after = [at for at, _ in b.requests() if stop_at <= at < first_stop]
    assert len(after) <= 1  # at most the exchange on the wire when it came
    assert RUN_WORD in b.words(1)
