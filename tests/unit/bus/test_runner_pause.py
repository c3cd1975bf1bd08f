"""The steady path in virtual time: polls carried in callbacks, interrupted in their pause.

The scripted line has a serial port's callback powers, so the master carries its polls as
it does on a real port (:mod:`fcmaster.bus.runner`): the reply is taken in the reader
callback, the next poll is chosen there and written by a timer when the pause ends. What
happens inside that pause — a shutdown cancelling the queue and its stops coming in — must
be seen when it ends: the stops go first and the poll chosen before them waits.

The scenario is a function that returns what went wrong, so the same check is run against
a deliberately broken runner (one that sends the chosen poll without asking whether it is
still next) and shown to catch it.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from fcmaster.bus import runner
from fcmaster.bus.commands import Outcome
from fcmaster.bus.planner import Planner, Step, StepKind
from tests.orders import orders
from tests.unit.bus.bench import PAUSE_S, STOP_WORD, T0, Bench, bench
from tests.unit.bus.test_master import A, B
from tests.unit.bus.test_master_pause import SHUTTING_DOWN, after

Scenario = Callable[[Bench], None]


async def stops_in_a_polls_pause() -> list[str]:
    """Shut down inside the pause after a poll's reply; what went wrong, if anything."""
    b = bench(A, B)
    problems: list[str] = []
    async with b.master:
        await b.clock.run_until(T0 + 0.5)  # both drives adopted: nothing but polls is queued
        in_flight = await b.mid_transaction()
        assert in_flight.reply_at is not None
        await b.clock.run_until(in_flight.reply_at)
        pause_ends = in_flight.reply_at + PAUSE_S
        assert b.transport.sent[-1] is in_flight  # inside the pause: the next poll is chosen
        assert b.clock.next_deadline() == pytest.approx(pause_ends)
        b.master.cancel_queued(SHUTTING_DOWN)  # what the service does at SIGTERM
        stops = [b.submit(orders(b.master, name).stop()) for name in ("a", "b")]
        for task in stops:
            await b.complete(task)
        outcomes = [task.result().outcome for task in stops]
        if outcomes != [Outcome.DONE, Outcome.DONE]:
            problems.append(f"stops ended {outcomes}")
    first_two = after(b, pause_ends)[:2]
    if first_two != [(1, STOP_WORD), (2, STOP_WORD)]:
        problems.append(f"first requests after the pause: {first_two}, not the two stops")
    return problems


async def test_the_master_carries_every_step_in_callbacks_on_the_scripted_line(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The virtual-time line runs the path a real serial port runs: every request — polls,
    # probes and commands alike — is written by the runner's callbacks, not by a task.
    # (A step's _go may choose again and send another: each request is counted once.)
    written_by_runner: dict[int, Step] = {}
    go = runner.LineRunner._go

    def counting_go(self: runner.LineRunner) -> None:
        step = self._step
        sent_before = len(b.transport.sent)
        go(self)
        if step is not None and len(b.transport.sent) > sent_before:
            written_by_runner.setdefault(sent_before, step)  # the innermost sent it

    monkeypatch.setattr(runner.LineRunner, "_go", counting_go)
    b = bench(A, B)
    async with b.master:
        await b.clock.run_until(T0 + 0.5)
        result = await b.complete(b.submit(orders(b.master, "a").stop()))
        await b.clock.run_until(T0 + 1.0)
    assert result.outcome is Outcome.DONE
    requests = len(b.transport.sent)
    assert requests > 20  # about 30 ms a poll at 19200
    assert len(written_by_runner) == requests
    assert any(step.kind is StepKind.COMMAND for step in written_by_runner.values())


async def test_stops_in_a_polls_pause_go_first_on_the_steady_path() -> None:
    assert await stops_in_a_polls_pause() == []


async def test_a_runner_that_sends_the_chosen_poll_regardless_is_caught(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Broken on purpose: the pause's timer sends the poll it chose, whatever came in.
    monkeypatch.setattr(Planner, "still_next", lambda self, step: True)
    problems = await stops_in_a_polls_pause()
    assert problems
    assert any("not the two stops" in problem for problem in problems)
