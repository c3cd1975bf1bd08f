import asyncio

import pytest

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.hub import EventsDropped, Hub
from fcmaster.protocol.codec import DriveStatus, Reply
from fcmaster.state import (
    AvailabilityChanged,
    CommandCompleted,
    ConditionChanged,
    DriveState,
    DriveUpdated,
    FleetState,
)
from tests.fakes import FakeClock


def _state(name: str, bus: str = "line1", hz: float | None = None) -> DriveState:
    return DriveState(
        name=name,
        bus=bus,
        address=1,
        protocol="danfoss-fc",
        control="monitor",
        output_frequency_hz=hz,
    )


def _alarm(drive: str, code: int) -> ConditionChanged:
    return ConditionChanged(
        bus="line1", drive=drive, kind="alarm", code=code, text=f"A{code}", active=True
    )


def test_snapshots_of_one_drive_conflate_to_the_latest() -> None:
    hub = Hub()
    sub = hub.subscribe()
    for hz in (10.0, 20.0, 30.0):
        hub.publish(DriveUpdated(_state("pump-1", hz=hz)))
    item = sub.get_nowait()
    assert isinstance(item, DriveUpdated)
    assert item.state.output_frequency_hz == 30.0
    assert sub.get_nowait() is None


def test_without_conflation_every_snapshot_arrives_in_order_within_the_bound() -> None:
    hub = Hub()
    every = hub.subscribe(conflate=False, max_events=3)
    latest = hub.subscribe()
    for hz in (10.0, 20.0, 30.0, 40.0):
        hub.publish(DriveUpdated(_state("pump-1", hz=hz)))
    assert every.get_nowait() == EventsDropped(1)
    taken = [every.get_nowait() for _ in range(3)]
    assert [u.state.output_frequency_hz for u in taken if isinstance(u, DriveUpdated)] == [
        20.0,
        30.0,
        40.0,
    ]
    assert every.get_nowait() is None
    assert latest.pending == 1  # the others still conflate


def test_a_conflated_snapshot_names_every_change_it_stands_for() -> None:
    hub = Hub()
    sub = hub.subscribe()
    hub.publish(DriveUpdated(_state("pump-1", hz=10.0), ("running", "output_frequency_hz")))
    hub.publish(DriveUpdated(_state("pump-1", hz=10.0), ("alarms",)))
    hub.publish(DriveUpdated(_state("pump-1", hz=10.0)))  # a heartbeat
    item = sub.get_nowait()
    assert isinstance(item, DriveUpdated)
    assert item.changed == ("running", "output_frequency_hz", "alarms")


def test_delivery_keeps_arrival_order_between_snapshots_and_events() -> None:
    hub = Hub()
    sub = hub.subscribe()
    hub.publish(DriveUpdated(_state("a", hz=1.0)))
    hub.publish(_alarm("a", 13))
    hub.publish(DriveUpdated(_state("b")))
    hub.publish(DriveUpdated(_state("a", hz=2.0)))  # conflates into the first, keeps its place
    got = [sub.get_nowait() for _ in range(3)]
    assert isinstance(got[0], DriveUpdated)
    assert got[0].state.name == "a"
    assert got[0].state.output_frequency_hz == 2.0
    assert got[1] == _alarm("a", 13)
    assert isinstance(got[2], DriveUpdated)
    assert got[2].state.name == "b"
    assert sub.get_nowait() is None


def test_discrete_events_are_bounded_and_drops_are_reported_first() -> None:
    hub = Hub()
    sub = hub.subscribe(max_events=3)
    for code in range(5):
        hub.publish(_alarm("a", code))
    assert sub.dropped == 2
    assert sub.get_nowait() == EventsDropped(2)
    codes = []
    while (item := sub.get_nowait()) is not None:
        assert isinstance(item, ConditionChanged)
        codes.append(item.code)
    assert codes == [2, 3, 4]


def test_a_stalled_subscriber_holds_one_snapshot_per_drive_however_many_arrive() -> None:
    hub = Hub()
    stalled = hub.subscribe(max_events=10)
    for i in range(10_000):
        hub.publish(DriveUpdated(_state(f"d{i % 50}", hz=float(i))))
    assert stalled.pending == 50


def test_filters_by_bus_drive_and_kind() -> None:
    hub = Hub()
    by_bus = hub.subscribe(bus="line2")
    by_drive = hub.subscribe(drive="a")
    by_kind = hub.subscribe(kinds=(AvailabilityChanged,))
    hub.publish(DriveUpdated(_state("a", bus="line1")))
    hub.publish(DriveUpdated(_state("b", bus="line2")))
    hub.publish(AvailabilityChanged(bus="line1", drive="b", online=False))
    assert [type(by_bus.get_nowait())] == [DriveUpdated]
    assert by_bus.get_nowait() is None
    got = by_drive.get_nowait()
    assert isinstance(got, DriveUpdated)
    assert got.state.name == "a"
    assert by_drive.get_nowait() is None
    assert by_kind.get_nowait() == AvailabilityChanged(bus="line1", drive="b", online=False)
    assert by_kind.get_nowait() is None


async def test_async_iteration_wakes_on_publish_and_ends_on_close() -> None:
    hub = Hub()
    sub = hub.subscribe()
    received: list[object] = []

    async def consume() -> None:
        async for item in sub:
            received.append(item)

    task = asyncio.create_task(consume())
    await asyncio.sleep(0)
    result = CommandResult(outcome=Outcome.DONE)
    event = CommandCompleted(
        bus="line1", drive="a", command=Command(action=Action.STOP), result=result
    )
    hub.publish(event)
    await asyncio.sleep(0)
    sub.close()
    async with asyncio.timeout(1):
        await task
    assert received == [event]
    assert hub.subscriptions == 0


def test_publishing_with_no_subscribers_is_harmless() -> None:
    hub = Hub()
    hub.publish(_alarm("a", 1))
    assert hub.published == 1


@pytest.mark.parametrize("max_events", [1, 2])
def test_snapshots_never_count_as_dropped(max_events: int) -> None:
    hub = Hub()
    sub = hub.subscribe(max_events=max_events)
    for i in range(100):
        hub.publish(DriveUpdated(_state("a", hz=float(i))))
    assert sub.dropped == 0


async def _settle() -> None:
    for _ in range(5):
        await asyncio.sleep(0)


async def test_wait_for_returns_at_once_when_the_condition_already_holds() -> None:
    hub = Hub()
    assert await hub.wait_for(lambda: "there") == "there"


async def test_wait_for_checks_again_after_each_publication_and_returns_what_it_found() -> None:
    hub = Hub()
    seen: list[float | None] = []
    latest: list[DriveState] = []

    def fast_enough() -> DriveState | None:
        state = latest[-1] if latest else None
        seen.append(None if state is None else state.output_frequency_hz)
        return state if state is not None and (state.output_frequency_hz or 0.0) > 20.0 else None

    waiting = asyncio.create_task(hub.wait_for(fast_enough))
    await _settle()
    assert seen == [None]  # checked once, then it waits: no polling
    assert hub.waiting == 1
    await _settle()
    assert seen == [None]
    for hz in (10.0, 30.0):
        latest.append(_state("pump-1", hz=hz))
        hub.publish(DriveUpdated(latest[-1]))
        await _settle()
    assert seen == [None, 10.0, 30.0]
    assert waiting.done()
    assert (await waiting).output_frequency_hz == 30.0


async def test_a_wait_that_times_out_leaves_the_hub_working() -> None:
    hub = Hub()
    sub = hub.subscribe()
    with pytest.raises(TimeoutError):
        await hub.wait_for(lambda: False, timeout_s=0)
    assert hub.waiting == 0  # the timed-out waiter left nothing behind
    hub.publish(_alarm("pump-1", 13))  # wakes nobody
    assert sub.get_nowait() == _alarm("pump-1", 13)
    assert await hub.wait_for(lambda: sub.pending == 0) is True


async def test_several_waiters_wake_on_one_publication() -> None:
    hub = Hub()
    ready: list[str] = []
    first = asyncio.create_task(hub.wait_for(lambda: "a" in ready))
    second = asyncio.create_task(hub.wait_for(lambda: "b" in ready))
    await _settle()
    ready.extend("ab")
    hub.publish(_alarm("pump-1", 9))
    await _settle()
    assert first.done()
    assert second.done()


async def test_a_wait_on_the_fleet_state_ends_with_the_reply_that_makes_it_true() -> None:
    hub, clock = Hub(), FakeClock()
    plan = DrivePlan(name="pump-1", address=1)
    fleet = FleetState(
        (LinePlan(name="line1", port="sim://line1", drives=(plan,)),),
        emit=hub.publish,
        clock=clock,
    )

    def running() -> DriveState | None:
        state = fleet.get("line1", "pump-1")
        return state if state is not None and state.running else None

    waiting = asyncio.create_task(hub.wait_for(running))
    status = DriveStatus(word=0x0607, running=False, fault=False, warning=False, at_reference=False)
    fleet.drive_replied("line1", plan, Reply(address=1, status=status), clock.now(), None)
    await _settle()
    assert not waiting.done()  # online now, but not running
    status = DriveStatus(word=0x0E07, running=True, fault=False, warning=False, at_reference=True)
    fleet.drive_replied("line1", plan, Reply(address=1, status=status), clock.now(), None)
    await _settle()
    assert waiting.done()
    assert (await waiting).status_word == 0x0E07
