"""What the MQTT bridge still has to send; it outlives every connection to the broker.

Theory of operation
-------------------
The hub side (state changes, events, command results) files messages here and never waits
for the broker; each connection's sender takes them out and publishes them. Memory stays
bounded whatever the broker does:

* **retained topics** (status, availability, state, discovery) keep only their latest
  payload; a topic is *dirty* until that payload has been handed to a sender, and a newer
  payload for a dirty topic replaces the older one in place (conflation, as in the hub);
* **results** of commands are kept, in order, until the broker has acknowledged them; they
  are few (one per command) and never dropped;
* **events** are kept in order up to ``max_events``; past that the oldest is dropped and
  counted.

The sender takes results first, then events, then dirty topics. A message taken is *in
flight* until :meth:`Outbox.sent`; when a connection ends, :meth:`Outbox.requeue` puts what
was in flight back at the head of its queue (QoS 1 is at-least-once: a result whose
acknowledgement was lost with the connection is sent again). On every new connection
:meth:`Outbox.republish` marks every retained topic dirty, because the broker may have lost
them (a restart without persistence) and a newcomer must find them.
"""

from __future__ import annotations

import asyncio
import enum
from collections import deque
from dataclasses import dataclass


class Kind(enum.Enum):
    """How a message is kept while it waits."""

    RETAINED = "retained"
    RESULT = "result"
    EVENT = "event"


@dataclass(slots=True, eq=False)
class Outgoing:
    """One message to publish (compared by identity while in flight)."""

    topic: str
    payload: bytes
    kind: Kind

    @property
    def retain(self) -> bool:
        """Whether the broker keeps it for later subscribers."""
        return self.kind is Kind.RETAINED


class Outbox:
    """Messages waiting for the broker (see the module docstring)."""

    def __init__(self, *, max_events: int = 1000) -> None:
        """An empty outbox that keeps up to ``max_events`` events."""
        self._retained: dict[str, bytes] = {}
        self._dirty: dict[str, None] = {}  # an ordered set of topics
        self._results: deque[Outgoing] = deque()
        self._events: deque[Outgoing] = deque()
        self._max_events = max_events
        self._in_flight: dict[Outgoing, None] = {}
        self._ready = asyncio.Event()
        self._progress = asyncio.Event()
        self.events_dropped = 0

    # -- filing ---------------------------------------------------------------------------

    def retain(self, topic: str, payload: bytes, *, force: bool = False) -> None:
        """Make ``payload`` the retained value of ``topic``; unchanged ones are not resent."""
        if not force and self._retained.get(topic) == payload:
            return
        self._retained[topic] = payload
        self._dirty[topic] = None
        self._ready.set()

    def result(self, topic: str, payload: bytes) -> None:
        """A command's result; kept until acknowledged."""
        self._results.append(Outgoing(topic, payload, Kind.RESULT))
        self._ready.set()

    def event(self, topic: str, payload: bytes) -> None:
        """An event; the oldest is dropped (and counted) when too many wait."""
        if len(self._events) >= self._max_events:
            self._events.popleft()
            self.events_dropped += 1
        self._events.append(Outgoing(topic, payload, Kind.EVENT))
        self._ready.set()

    # -- the sender's side ----------------------------------------------------------------

    @property
    def pending(self) -> int:
        """Messages waiting to be taken."""
        return len(self._results) + len(self._events) + len(self._dirty)

    @property
    def in_flight(self) -> int:
        """Messages taken and not yet reported sent."""
        return len(self._in_flight)

    def take(self) -> Outgoing | None:
        """The next message to publish (it is then in flight), or None."""
        if self._results:
            message = self._results.popleft()
        elif self._events:
            message = self._events.popleft()
        elif self._dirty:
            topic = next(iter(self._dirty))
            del self._dirty[topic]
            message = Outgoing(topic, self._retained[topic], Kind.RETAINED)
        else:
            return None
        self._in_flight[message] = None
        return message

    async def wait(self) -> None:
        """Return once there is something to take."""
        while not self.pending:
            self._ready.clear()
            await self._ready.wait()

    def sent(self, message: Outgoing) -> None:
        """The broker has ``message``."""
        self._in_flight.pop(message, None)
        self._progress.set()

    def requeue(self) -> None:
        """Put every message in flight back at the head of its queue (connection lost)."""
        for message in reversed(self._in_flight):
            if message.kind is Kind.RESULT:
                self._results.appendleft(message)
            elif message.kind is Kind.EVENT:
                self._events.appendleft(message)
            elif message.topic not in self._dirty:  # else a newer payload is already due
                self._dirty[message.topic] = None
        self._in_flight.clear()
        self._ready.set()
        self._progress.set()

    def republish(self) -> None:
        """Mark every retained topic dirty (a new connection)."""
        self._dirty = dict.fromkeys(self._retained)
        if self._dirty:
            self._ready.set()

    async def flushed(self) -> None:
        """Return once nothing waits and nothing is in flight."""
        while self.pending or self._in_flight:
            self._progress.clear()
            await self._progress.wait()
