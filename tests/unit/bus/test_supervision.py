"""Supervision in virtual time: nothing unexpected ends a line silently.

An observer that raises is kept away from the line; a port driver or a loop that raises an
unexpected exception takes the line down with the reason, ends the queued commands, and the
line is served again after a backoff.
"""

from __future__ import annotations

import random

import pytest
from structlog.testing import capture_logs

from fcmaster.bus.commands import Outcome
from fcmaster.bus.master import BACKOFF_FIRST_S
from fcmaster.bus.plan import DrivePlan
from fcmaster.protocol.codec import Reply
from fcmaster.protocol.drive import ControlIntent
from tests.orders import orders
from tests.unit.bus.bench import T0, Recorder, bench

A = DrivePlan(name="a", address=1, control=True)
B = DrivePlan(name="b", address=2)


def approx(value: float) -> object:
    return pytest.approx(value, abs=1e-9)


class Faulty(Recorder):
    """An observer with a bug: every reply it is told about raises."""

    def drive_replied(
        self, bus: str, drive: DrivePlan, reply: Reply, at: float, commanded: ControlIntent | None
    ) -> None:
        super().drive_replied(bus, drive, reply, at, commanded)
        raise KeyError("observer bug")


async def test_an_observer_that_raises_is_logged_and_the_line_goes_on() -> None:
    b = bench(A, B, recorder=Faulty)
    faulty = b.observer
    with capture_logs() as logs:
        async with b.master:
            await b.clock.run_until(T0 + 0.5)
            result = await b.complete(b.submit(orders(b.master, "a").start(reference_pct=20.0)))
            sent = len(b.transport.sent)
            await b.clock.run_for(0.5)
    assert result.outcome is Outcome.DONE
    assert len(b.transport.sent) > sent + 10  # still polling
    assert b.master.stats.observer_errors == len(faulty.replies) > 10
    assert b.master.stats.crashes == 0
    assert b.drives[1].running
    failed = [e for e in logs if e["event"] == "bus.observer_failed"]
    assert failed[0]["call"] == "drive_replied"
    assert "KeyError" in failed[0]["error"]
    assert not [e for e in logs if e["event"] in ("bus.crashed", "bus.lost")]


async def test_a_port_driver_raising_on_open_is_retried_and_the_reason_shown() -> None:
    b = bench(A, seed=5)
    b.transport.open_error = NotImplementedError("write_timeout is currently not supported")
    with capture_logs() as logs:
        async with b.master:
            assert not b.master.is_up
            reason = b.master.stats.to_json(b.clock.now())["down_reason"]
            result = await b.complete(b.submit(orders(b.master, "a").stop()))
            await b.clock.run_for(2.0)
            assert b.master.is_up
            assert b.master.stats.down_reason is None
    expected = (
        "internal error in open: NotImplementedError: write_timeout is currently not supported"
    )
    assert reason == expected
    assert result.outcome is Outcome.CANCELLED
    assert result.reason == f"line1 is down: {expected}"
    delay = BACKOFF_FIRST_S * (0.8 + 0.4 * random.Random(5).random())
    assert b.transport.open_attempts == [T0, approx(T0 + delay)]
    assert b.transport.sent[0].at == approx(T0 + delay)
    (crashed,) = [e for e in logs if e["event"] == "bus.crashed"]
    assert crashed["during"] == "open"
    assert crashed["log_level"] == "error"
    assert b.master.stats.crashes == 1


async def test_a_loop_that_raises_takes_the_line_down_ends_commands_and_restarts() -> None:
    b = bench(A, B, seed=9)
    with capture_logs() as logs:
        async with b.master:
            await b.clock.run_until(T0 + 0.3)
            in_flight = await b.mid_transaction()
            b.transport.read_error = RuntimeError("driver bug")
            queued = [
                b.submit(orders(b.master, "a").start(reference_pct=10.0)),
                b.submit(orders(b.master, "b").read("16-13")),
            ]
            # The read under way finishes; the next one (the start's) raises.
            await b.clock.run_until((in_flight.reply_at or 0.0) + 0.01)
            assert not b.master.is_up
            crashed_at = b.observer.lines[-1][2]
            shown = b.master.stats.to_json(b.clock.now())["down_reason"]
            await b.clock.run_for(2.0)
            assert b.master.is_up
            after = await b.complete(b.submit(orders(b.master, "b").read("16-13")))
    reason = "internal error in serve: RuntimeError: driver bug"
    assert shown == reason
    for task in queued:
        assert task.result().outcome is Outcome.CANCELLED
        assert task.result().reason == f"line1 stopped: {reason}"
    assert after.outcome is Outcome.DONE
    assert [(up, why) for up, why, _ in b.observer.lines] == [
        (True, ""),
        (False, reason),
        (True, ""),
    ]
    delay = BACKOFF_FIRST_S * (0.8 + 0.4 * random.Random(9).random())
    assert b.transport.open_attempts == [T0, approx(crashed_at + delay)]
    assert b.transport.closed == 2  # after the crash, and at shutdown
    (crashed,) = [e for e in logs if e["event"] == "bus.crashed"]
    assert crashed["during"] == "serve"
    assert crashed["recent_frames"]  # the flight recorder goes with it
    assert crashed["recent_frames"][-1].startswith("tx ")
    assert {(n, online) for n, online, _ in b.observer.availability if not online} == {
        ("a", False),
        ("b", False),
    }
    assert b.master.stats.crashes == 1
    assert b.master.stats.reopens == 1
