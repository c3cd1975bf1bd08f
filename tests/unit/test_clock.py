"""MonotonicClock and the precise event loop: waits never end before their deadline."""

import asyncio
import os
import time
from functools import partial

import pytest

from fcmaster.clock import MonotonicClock, new_event_loop

# Around the spin threshold, a typical pause (2 characters at 115200 and at 19200 baud),
# and past it: spun whole, slept and spun, slept.
DELAYS_S = (0.0, 0.00002, MonotonicClock.SPIN_S, 0.00019, 0.0012, 0.005)


async def _wake_ups(clock: MonotonicClock) -> list[tuple[float, float]]:
    """(deadline, returned) for each delay, several times over so the clock learns."""
    seen = []
    for _ in range(5):
        for delay in DELAYS_S:
            deadline = clock.now() + delay
            await clock.sleep_until(deadline)
            seen.append((deadline, clock.now()))
    return seen


def test_waits_on_the_precise_loop_never_end_before_their_deadline() -> None:
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        seen = runner.run(_wake_ups(MonotonicClock()))
    assert all(returned >= deadline for deadline, returned in seen)


async def test_waits_on_the_default_loop_never_end_before_their_deadline() -> None:
    seen = await _wake_ups(MonotonicClock())
    assert all(returned >= deadline for deadline, returned in seen)


async def test_sleep_waits_at_least_as_long_as_asked() -> None:
    clock = MonotonicClock()
    for seconds in (0.00005, 0.002):
        started = time.monotonic()
        await clock.sleep(seconds)
        assert time.monotonic() - started >= seconds


async def test_a_deadline_that_has_passed_returns_without_waiting_for_the_loop() -> None:
    clock = MonotonicClock()
    ran = False

    async def other() -> None:
        nonlocal ran
        ran = True

    task = asyncio.create_task(other())
    await clock.sleep_until(clock.now() - 1.0)
    assert not ran  # nothing else got a turn: the call did not yield
    await task


async def test_a_long_wait_can_be_cancelled() -> None:
    clock = MonotonicClock()
    sleeper = asyncio.create_task(clock.sleep(10.0))
    await asyncio.sleep(0.001)
    sleeper.cancel()
    with pytest.raises(asyncio.CancelledError):
        await sleeper


class _FakeTime:
    """Stands in for ``time`` and ``asyncio`` inside fcmaster.clock: sleeps end on time."""

    def __init__(self) -> None:
        self.now = 100.0
        self.sleeps: list[float] = []

    def monotonic(self) -> float:
        return self.now

    async def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        self.now += seconds


async def test_a_long_wait_ends_with_a_short_sleep(monkeypatch: pytest.MonkeyPatch) -> None:
    # The kernel wakes a 10 ms sleep later than the lead can cover (a Mitsubishi
    # turnaround): the sleep that lands on the deadline must be a short one.
    fake = _FakeTime()
    monkeypatch.setattr("fcmaster.clock.time", fake)
    monkeypatch.setattr("fcmaster.clock.asyncio", fake)
    clock = MonotonicClock()
    deadline = fake.now + 0.010
    await clock.sleep_until(deadline)
    assert fake.now >= deadline
    assert len(fake.sleeps) == 2
    assert fake.sleeps[-1] <= 0.001 + 1e-9
    assert sum(fake.sleeps) == pytest.approx(0.010)


def _note_time(clock: MonotonicClock, called: asyncio.Future[float]) -> None:
    called.set_result(clock.now())


async def _called_at(clock: MonotonicClock) -> list[tuple[float, float]]:
    """(deadline, called) for each delay through call_at, several times over."""
    seen = []
    for _ in range(5):
        for delay in (*DELAYS_S, 0.012):  # the last one is split, as a long sleep is
            deadline = clock.now() + delay
            called: asyncio.Future[float] = asyncio.get_running_loop().create_future()
            clock.call_at(deadline, partial(_note_time, clock, called))
            seen.append((deadline, await called))
    return seen


def test_calls_on_the_precise_loop_never_come_before_their_deadline() -> None:
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        seen = runner.run(_called_at(MonotonicClock()))
    assert all(called >= deadline for deadline, called in seen)


async def test_calls_on_the_default_loop_never_come_before_their_deadline() -> None:
    seen = await _called_at(MonotonicClock())
    assert all(called >= deadline for deadline, called in seen)


async def test_a_call_cancelled_is_not_made_even_after_a_split() -> None:
    clock = MonotonicClock()
    calls: list[str] = []
    short = clock.call_at(clock.now() + 0.001, lambda: calls.append("short"))
    long = clock.call_at(clock.now() + 0.02, lambda: calls.append("long"))
    short.cancel()
    await asyncio.sleep(0.015)  # the long one's first stretch has passed: it is re-armed
    long.cancel()
    await asyncio.sleep(0.03)
    assert calls == []


async def test_a_call_due_already_is_made_on_the_next_turn_of_the_loop() -> None:
    clock = MonotonicClock()
    calls: list[str] = []
    clock.call_at(clock.now() - 1.0, lambda: calls.append("due"))
    assert calls == []  # never from inside call_at
    await asyncio.sleep(0)
    assert calls == ["due"]


def test_a_brief_wait_is_spun_to_its_deadline_and_a_longer_one_left_to_a_timer() -> None:
    clock = MonotonicClock()
    clock._early = 0.0005  # as if wake-ups came half a millisecond late
    for _ in range(20):
        deadline = clock.now() + 0.0002
        assert clock.wait_briefly(deadline)
        assert clock.now() >= deadline
    started = clock.now()
    assert not clock.wait_briefly(started + 0.01)
    assert clock.now() < started + 0.01  # it left the wait to a timer: not spun to its end
    assert clock.wait_briefly(started - 1.0)  # passed already: nothing to wait


async def _close_behind_the_loops_back() -> str:
    """A reader registered on a descriptor that is then closed without removing it."""
    loop = asyncio.get_running_loop()
    read_end, write_end = os.pipe()
    loop.add_reader(read_end, lambda: None)
    os.close(read_end)  # as a library that registers from another thread can leave it
    os.close(write_end)
    await asyncio.sleep(0.01)  # the loop selects, finds the closed descriptor, goes on
    loop.remove_reader(read_end)  # the owner's late remove finds nothing, as asyncio allows
    return "alive"


def test_the_precise_loop_outlives_a_descriptor_closed_while_registered() -> None:
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        assert runner.run(_close_behind_the_loops_back()) == "alive"
