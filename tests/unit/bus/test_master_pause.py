"""BusMaster in virtual time: what comes in or ends during the pause after a reply.

The master chooses the next step as soon as a reply is in and sends it when the pause
after that reply is over. Whatever happens in between — a shutdown cancelling the queue, a
stop superseding the chosen command, a newer reference taking its place, a stop for
another drive — is seen when the pause ends: a command that has ended is never sent, and
what goes out is what the queue holds then. Each test stops the master right inside such a
pause, with a command for drive b already chosen.
"""

from __future__ import annotations

import asyncio

import pytest
import structlog.testing

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.protocol.danfoss_fc import ControlWord, encode_reference
from tests.orders import orders
from tests.unit.bus.bench import PAUSE_S, STOP_WORD, T0, Bench, bench
from tests.unit.bus.fcdrive import FcDrive
from tests.unit.bus.test_master import A, B

SHUTTING_DOWN = "fcmaster is shutting down"


async def in_the_pause_with(
    b: Bench, command: Command
) -> tuple[asyncio.Task[CommandResult], float]:
    """Queue ``command`` for b while a request is on the wire; run until that reply is in.

    The master has then chosen ``command`` and waits for the pause to end. Returns its task
    and the time the pause ends.
    """
    in_flight = await b.mid_transaction()
    task = b.submit(orders(b.master, "b").execute(command))
    assert in_flight.reply_at is not None
    await b.clock.run_until(in_flight.reply_at)
    assert b.transport.sent[-1] is in_flight  # nothing more yet: we are inside the pause
    assert b.clock.next_deadline() == in_flight.reply_at + PAUSE_S
    return task, in_flight.reply_at + PAUSE_S


def after(b: Bench, when: float) -> list[tuple[int, int]]:
    """(address, control word) of every request written from ``when`` on."""
    return [(t.address, t.pcd1) for at, t in b.requests() if at >= when - 1e-9]


def runs(word: int) -> bool:
    return bool(word & ControlWord.START) and bool(word & ControlWord.DATA_VALID)


async def test_shutdown_in_the_pause_cancels_the_chosen_command_and_the_stops_go_out() -> None:
    b = bench(A, B)
    with structlog.testing.capture_logs() as logs:
        async with b.master:
            await b.clock.run_until(T0 + 0.2)
            start, pause_ends = await in_the_pause_with(
                b, Command(action=Action.START, reference_pct=40.0)
            )
            b.master.cancel_queued(SHUTTING_DOWN)  # what the service does at SIGTERM
            stops = [b.submit(orders(b.master, name).stop()) for name in ("a", "b")]
            for task in stops:
                await b.complete(task)
            assert b.master.is_up
    assert start.result() == CommandResult(outcome=Outcome.CANCELLED, reason=SHUTTING_DOWN)
    assert [task.result().outcome for task in stops] == [Outcome.DONE, Outcome.DONE]
    wire = after(b, pause_ends)
    assert wire[:2] == [(1, STOP_WORD), (2, STOP_WORD)]  # the first request after the pause
    assert not [word for _, word in wire if runs(word)]
    assert not b.drives[2].running
    assert not [e for e in logs if e["log_level"] in ("error", "critical")]
    assert b.master.stats.crashes == 0


async def test_a_stop_in_the_pause_supersedes_the_chosen_start_which_never_goes_out() -> None:
    b = bench(A, B)
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        start, pause_ends = await in_the_pause_with(
            b, Command(action=Action.START, reference_pct=40.0)
        )
        stop = b.submit(orders(b.master, "b").stop())
        await b.complete(stop)
        await b.clock.run_for(0.1)
        assert b.master.is_up
    assert start.result().outcome is Outcome.SUPERSEDED
    assert stop.result().outcome is Outcome.DONE
    wire = after(b, pause_ends)
    assert wire[0] == (2, STOP_WORD)
    assert not [word for address, word in wire if address == 2 and runs(word)]
    assert not b.drives[2].running
    assert b.master.stats.crashes == 0


async def test_a_stop_for_another_drive_in_the_pause_goes_before_the_chosen_command() -> None:
    b = bench(A, B)
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        read, pause_ends = await in_the_pause_with(
            b, Command(action=Action.READ, parameter="16-13")
        )
        stop = b.submit(orders(b.master, "a").stop())
        await b.complete(read)
        await b.complete(stop)
    assert [read.result().outcome, stop.result().outcome] == [Outcome.DONE, Outcome.DONE]
    assert [t.address for at, t in b.requests() if at >= pause_ends - 1e-9][:2] == [1, 2]


async def test_a_newer_reference_in_the_pause_is_the_one_sent_and_reported_done() -> None:
    b = bench(A, B, fc=[FcDrive(1), FcDrive(2, running=True, output_pct=50.0)])
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        older, pause_ends = await in_the_pause_with(
            b, Command(action=Action.SET_REFERENCE, reference_pct=20.0)
        )
        newer = b.submit(orders(b.master, "b").set_reference(reference_pct=30.0))
        await b.complete(newer)
        await b.clock.run_for(0.1)
    assert older.result().outcome is Outcome.SUPERSEDED
    assert newer.result().outcome is Outcome.DONE
    references = [t.pcd2 for at, t in b.requests(2) if at >= pause_ends - 1e-9]
    assert encode_reference(20.0) not in references
    assert references[0] == encode_reference(30.0)
    assert b.drives[2].output_pct == pytest.approx(30.0, abs=0.01)
