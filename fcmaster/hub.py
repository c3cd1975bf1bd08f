"""Fan-out of fleet events to subscribers that never slow the bus.

Theory of operation
-------------------
:meth:`Hub.publish` is called on the bus's path, so it only files the event with each
matching subscription and returns; no subscriber code runs there. A subscription keeps two
things, and its memory is bounded whatever the subscriber does:

* the latest :class:`~fcmaster.state.DriveUpdated` per drive — a newer snapshot replaces an
  undelivered older one in place (conflation: at most one pending snapshot per drive),
  keeping the names of the fields both changed;
* discrete events (alarms, availability, command results, line changes) in order, up to
  ``max_events``; past that the oldest is dropped and counted, and the subscriber is told
  with an :class:`EventsDropped` before the next event it receives.

A subscriber that must see every snapshot (a store-and-forward queue: a value superseded
before it read it would be missing from the history) subscribes with ``conflate=False``:
its snapshots are then kept in order like discrete events, within the same bound.

Delivery keeps arrival order: each pending item carries the sequence number it was filed
under (a snapshot keeps the number of its first undelivered version), and the consumer takes
whichever head is older.

:meth:`Hub.wait_for` waits for a condition on the fleet (or anything the publications
follow) without polling: the condition is checked at once, then again after each
publication. Publishing only wakes the waiters (it runs none of their code), and costs one
test when nobody waits. A change that is never published is seen at the drive's next
publication: a value moving within its deadband, at the heartbeat at the latest.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import TypeVar

from fcmaster.state import DriveUpdated, Event

DEFAULT_MAX_EVENTS = 1000
T = TypeVar("T")


@dataclass(slots=True, frozen=True)
class EventsDropped:
    """Discrete events were dropped because this subscriber fell behind."""

    count: int


class Subscription:
    """One subscriber's view of the hub. Iterate with ``async for``; close when done."""

    def __init__(
        self,
        hub: Hub,
        *,
        bus: str | None,
        drive: str | None,
        kinds: tuple[type, ...] | None,
        max_events: int,
        conflate: bool = True,
    ) -> None:
        self._hub = hub
        self.conflate = conflate
        self.bus = bus
        self.drive = drive
        self.kinds = kinds
        self._max_events = max_events
        self._seq = 0
        self._events: deque[tuple[int, Event]] = deque()
        self._latest: dict[str, tuple[int, DriveUpdated]] = {}
        self._ready = asyncio.Event()
        self._unreported = 0
        self.dropped = 0
        self.closed = False

    def matches(self, event: Event) -> bool:
        """Whether ``event`` passes this subscription's filters."""
        if self.kinds is not None and not isinstance(event, self.kinds):
            return False
        if self.bus is not None and event.bus != self.bus:
            return False
        return self.drive is None or event.drive == self.drive

    def offer(self, event: Event) -> None:
        """File ``event`` (called by the hub; never blocks)."""
        self._seq += 1
        if isinstance(event, DriveUpdated) and self.conflate:
            key = event.state.key
            pending = self._latest.get(key)
            if pending is None:
                self._latest[key] = (self._seq, event)
            else:
                self._latest[key] = (pending[0], event.after(pending[1]))
        else:
            if len(self._events) >= self._max_events:
                self._events.popleft()
                self.dropped += 1
                self._unreported += 1
            self._events.append((self._seq, event))
        self._ready.set()

    @property
    def pending(self) -> int:
        """Items waiting for the subscriber."""
        return len(self._events) + len(self._latest)

    def get_nowait(self) -> Event | EventsDropped | None:
        """The next item, or None when there is none."""
        if self._unreported:
            count, self._unreported = self._unreported, 0
            return EventsDropped(count)
        events, latest = self._events, self._latest
        if latest:
            key = next(iter(latest))
            seq, update = latest[key]
            if not events or seq < events[0][0]:
                del latest[key]
                return update
        if events:
            return events.popleft()[1]
        return None

    async def get(self) -> Event | EventsDropped:
        """The next item, waiting for one."""
        while True:
            item = self.get_nowait()
            if item is not None:
                return item
            if self.closed:
                raise StopAsyncIteration
            self._ready.clear()
            await self._ready.wait()

    def __aiter__(self) -> AsyncIterator[Event | EventsDropped]:
        return self

    async def __anext__(self) -> Event | EventsDropped:
        return await self.get()

    def close(self) -> None:
        """Stop receiving; a waiting ``async for`` ends."""
        if not self.closed:
            self.closed = True
            self._hub.unsubscribe(self)
            self._ready.set()

    def __enter__(self) -> Subscription:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class Hub:
    """Distributes fleet events to subscriptions."""

    def __init__(self) -> None:
        self._subscriptions: list[Subscription] = []
        self._waiters: list[asyncio.Future[None]] = []  # woken by the next publication
        self.published = 0

    def subscribe(
        self,
        *,
        bus: str | None = None,
        drive: str | None = None,
        kinds: tuple[type, ...] | None = None,
        max_events: int = DEFAULT_MAX_EVENTS,
        conflate: bool = True,
    ) -> Subscription:
        """A new subscription to events matching the filters (None: everything).

        ``conflate=False``: every snapshot in order (bounded by ``max_events``), not the latest.
        """
        subscription = Subscription(
            self, bus=bus, drive=drive, kinds=kinds, max_events=max_events, conflate=conflate
        )
        self._subscriptions.append(subscription)
        return subscription

    def unsubscribe(self, subscription: Subscription) -> None:
        """Remove a subscription (its ``close`` calls this)."""
        if subscription in self._subscriptions:
            self._subscriptions.remove(subscription)

    def publish(self, event: Event) -> None:
        """File ``event`` with every matching subscription; returns at once."""
        self.published += 1
        for subscription in self._subscriptions:
            if subscription.matches(event):
                subscription.offer(event)
        if self._waiters:
            waiters, self._waiters = self._waiters, []
            for waiter in waiters:
                if not waiter.done():
                    waiter.set_result(None)

    async def wait_for(
        self, condition: Callable[[], T | None], *, timeout_s: float | None = None
    ) -> T:
        """Wait until ``condition()`` is true, checked now and after each publication.

        Returns what ``condition`` returned (so it can hand back the state it found);
        TimeoutError after ``timeout_s`` of the event loop's time (None: no limit).
        """
        async with asyncio.timeout(timeout_s):
            while True:
                found = condition()
                if found:
                    return found
                waiter = asyncio.get_running_loop().create_future()
                self._waiters.append(waiter)
                try:
                    await waiter
                except asyncio.CancelledError:  # timed out or cancelled: leave nothing behind
                    if waiter in self._waiters:
                        self._waiters.remove(waiter)
                    raise

    @property
    def waiting(self) -> int:
        """How many ``wait_for`` calls wait for the next publication."""
        return len(self._waiters)

    @property
    def subscriptions(self) -> int:
        """How many subscriptions are open."""
        return len(self._subscriptions)

    def dropped(self) -> int:
        """Discrete events dropped across open subscriptions."""
        return sum(s.dropped for s in self._subscriptions)
