"""The Sparkplug B edge node: the fleet's change stream in, births, data and deaths out.

Theory of operation
-------------------
The adapter joins three parts to one aiomqtt session at a time: the
:class:`~fcmaster.adapters.sparkplug.node.EdgeNode` (what to publish, with seq and bdSeq),
the :class:`~fcmaster.adapters.sparkplug.forward.Forward` store (every change on disk until
the broker is known to have it) and :class:`~fcmaster.adapters.sparkplug.commands.DeviceCommands`
(DCMD through the gateway). Its tasks:

* the **pump** reads the hub subscription (it never makes the bus wait: the hub only files
  each snapshot, in order and up to a bound — not conflated, since a value superseded before
  the pump read it would be missing from the history) and turns each drive's snapshot into
  readings: a drive come online is a DBIRTH,
  gone offline a DDEATH, otherwise what changed is numbered and stored, and, when the node
  is online, queued as a DDATA. Nothing here waits for the broker.
* the **connection loop** takes the next ``bdSeq`` (kept in a file beside the store before the
  CONNECT), connects with the NDEATH as the Will at QoS 1, subscribes to NCMD, DCMD and the
  primary host's STATE, and lets the node decide when to be born. When the connection fails
  it waits — exponential from ``reconnect_min_s`` to ``reconnect_max_s``, with jitter — and
  starts again; a node that must leave (the host went offline) publishes its NDEATH and
  disconnects cleanly first.
* in a session, the **sender** publishes the queue in order (seq is given as a message is
  queued, so the queue's order is the wire's); the **barrier** task asks the broker for an
  UNSUBACK now and then and confirms to the store what was published before it; the
  **drain** publishes stored history (``is_historical``) oldest first, in messages of at
  most :data:`HISTORY_MESSAGE_ROWS` changes, one at a time, and only while live data keeps
  up (see :meth:`SparkplugAdapter._live_first`): live data never waits behind more than one
  history message, and history slows down as soon as live data is late.

Live data is late when the process has more to do than it can (history's reading, encoding
and writing is work too, beside the bus and the other adapters): a live message waits in the
queue, the hub holds snapshots the pump has not read, or a live message took longer than
:data:`LIVE_LAG_S` from its queueing to its writing to the socket, or the drain's own sleep
ended that much late (the loop was busy). The drain then waits and halves its pace; while
live data keeps up, its pace grows back to :data:`HISTORY_ROWS_PER_S`.

Shutdown: commands get a bounded grace, the node publishes its NDEATH (it is leaving, so the
broker's Will is not needed) and disconnects, and the store writes what is queued.
"""

from __future__ import annotations

import asyncio
import contextlib
import random
import socket
from collections import deque
from types import TracebackType
from urllib.parse import urlsplit

import aiomqtt
import structlog

from fcmaster.adapters.gateway import Gateway
from fcmaster.adapters.mqtt import _cancel, _refused, _tls_context
from fcmaster.adapters.settings import SparkplugSettings
from fcmaster.adapters.sparkplug.commands import DeviceCommands
from fcmaster.adapters.sparkplug.forward import Change, Forward, bd_seq_path, next_bd_seq
from fcmaster.adapters.sparkplug.metrics import (
    LAST_OUTCOME,
    LAST_REASON,
    Reading,
    changed,
    device_readings,
)
from fcmaster.adapters.sparkplug.node import (
    Disconnect,
    EdgeNode,
    Effect,
    Phase,
    Publish,
    command_metrics,
)
from fcmaster.adapters.sparkplug.payload import DataType
from fcmaster.bus.commands import CommandResult
from fcmaster.errors import FcmasterError
from fcmaster.hub import EventsDropped, Subscription
from fcmaster.state import DriveState, DriveUpdated

__all__ = ["SparkplugAdapter"]

log = structlog.get_logger("fcmaster.adapters.sparkplug")

COMMAND_GRACE_S = 5.0  # at shutdown, how long running commands may take to end
LEAVE_S = 2.0  # at shutdown, how long the NDEATH and the disconnect may take
BARRIER_S = 0.2  # how often what was published is confirmed to the store
DRAIN_IDLE_S = 0.5  # how often an empty store is looked at again
HISTORY_ROWS_PER_S = 5000.0  # the drain's pace, at most
HISTORY_MIN_ROWS_PER_S = 50.0  # the pace it slows to, at least, while live data is late
HISTORY_MESSAGE_ROWS = 50  # changes per history message, at most
# Live data this late (queued → written, or the loop's wake-up) holds history back: a
# fraction of the second a host may take to see a change.
LIVE_LAG_S = 0.1
MAX_QUEUED = 20_000  # queued live messages past which the broker is too slow: reconnect
MAX_IN_FLIGHT = 256  # publications handed to the connection and not yet written, at once
MAX_BEHIND = 100_000  # drive snapshots the pump may fall behind before the oldest are dropped

# A queued message: the effect (None: a change told by no message), the number of the change
# it carries (None: none), when it was queued, and whether it is history.
_Out = tuple[Effect | None, int | None, float, bool]


class _Leave(FcmasterError):
    """The node leaves the session on purpose (its NDEATH is published)."""


class SparkplugAdapter:
    """A Sparkplug B 3.0 edge node for one gateway; an async context manager."""

    def __init__(
        self, settings: SparkplugSettings, gateway: Gateway, *, demo: bool = False
    ) -> None:
        """An edge node for ``gateway``'s drives on the broker ``settings`` names.

        ``demo`` changes nothing here. ConfigError for settings that cannot work (TLS files).
        """
        self._settings = settings
        self._gateway = gateway
        self._clock = gateway.clock
        self.node = EdgeNode(
            group_id=settings.group_id,
            edge_node_id=settings.edge_node_id,
            primary_host_id=settings.primary_host_id,
            rebirth_min_s=settings.rebirth_min_s,
        )
        self.forward = Forward(
            settings.store,
            max_bytes=int(settings.store_max_mb * 1024 * 1024),
            max_age_s=settings.store_max_days * 86400.0,
        )
        self._bd_path = bd_seq_path(settings.store)
        self._bd_seq: int | None = None
        self.client_id = (
            settings.client_id or f"fcmaster-spb-{settings.group_id}-{settings.edge_node_id}"
        )
        parts = urlsplit(settings.url)
        self._host = parts.hostname or ""
        self._port = parts.port or (8883 if parts.scheme == "mqtts" else 1883)
        self._tls = _tls_context(settings, "sparkplug") if parts.scheme == "mqtts" else None
        self.actor = f"sparkplug:{settings.edge_node_id}"
        self._desk = DeviceCommands(
            gateway, enabled=settings.commands, actor=self.actor, answer=self._answer
        )
        self._readings: dict[str, dict[str, Reading]] = {}
        self._online: dict[str, bool] = {}
        self._buses: dict[str, str] = {}
        self._outcomes: dict[str, tuple[str, str]] = {}
        self._nominal_hz: dict[str, float] = {}
        # The session's outgoing messages in wire order; each with the number of the change
        # it carries (None: not a change), so the barrier knows what it confirms, when it
        # was queued and whether it is history.
        self._queue: deque[_Out] = deque()
        self._queued = asyncio.Event()
        self._idle = asyncio.Event()  # the queue is empty
        self._history_out = 0  # history messages queued or handed over and not yet written
        self._history_written = asyncio.Event()
        self._lag_s = 0.0  # the latest live data has been since the drain last looked
        self._pace = _Pace()
        self.history_messages = 0  # history messages handed to the connection
        self.history_held = 0  # times the drain waited because live data was late
        self._sent_n = 0
        self._tasks: list[asyncio.Task[None]] = []
        self._subscription: Subscription | None = None
        self._client: aiomqtt.Client | None = None
        self._rng = random.Random()
        self._entered = False
        self._was_online = False  # the node's phase as the store last heard of it
        self.connected = asyncio.Event()
        self.connections = 0
        self.barriers = 0  # barriers asked for
        self.barriers_answered = 0

    # -- lifecycle ------------------------------------------------------------------------

    async def __aenter__(self) -> SparkplugAdapter:
        """Start: read every drive's state, open the store, connect in the background."""
        if self._entered:
            raise RuntimeError("SparkplugAdapter is not re-entrant")
        self._entered = True
        # Every snapshot, not the latest: each change is kept for the store (bounded; what
        # falls off a pump this far behind is counted and logged).
        self._subscription = self._gateway.hub.subscribe(
            kinds=(DriveUpdated,), conflate=False, max_events=MAX_BEHIND
        )
        self.forward.start()
        for state in self._gateway.fleet.snapshot():  # where things stand: told by the births
            self._readings[state.name] = self._readings_of(state)
            self._online[state.name] = state.online
            self._buses[state.name] = state.bus
        self._tasks = [
            asyncio.create_task(self._pump(self._subscription), name="sparkplug.pump"),
            asyncio.create_task(self._connect_forever(), name="sparkplug.connection"),
        ]
        for task in self._tasks:
            task.add_done_callback(_report_crash)
        log.info(
            "sparkplug.started",
            url=self._settings.url,
            group_id=self._settings.group_id,
            edge_node_id=self._settings.edge_node_id,
            primary_host_id=self._settings.primary_host_id,
        )
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        """Stop: end the commands, publish the NDEATH, disconnect, close the store."""
        try:
            await self._desk.close(COMMAND_GRACE_S)
            pump, connection = self._tasks
            await _cancel(pump)
            client = self._client
            if client is not None and self.node.phase is Phase.ONLINE:  # a host saw it born
                death = self.node.death(self._now_ms())
                with contextlib.suppress(aiomqtt.MqttError, TimeoutError):
                    await client.publish(death.topic, death.payload, qos=1, timeout=LEAVE_S)
            await _cancel(connection, grace_s=LEAVE_S)
        finally:
            if self._subscription is not None:
                self._subscription.close()
            await asyncio.to_thread(self.forward.close)
            self._entered = False
            log.info("sparkplug.stopped", stored=self.forward.last_n)

    # -- the fleet's changes ----------------------------------------------------------------

    async def _pump(self, subscription: Subscription) -> None:
        async for item in subscription:
            if isinstance(item, DriveUpdated):
                self._update(item.state)
            elif isinstance(item, EventsDropped):
                log.warning("sparkplug.events_dropped", count=item.count)

    def _readings_of(self, state: DriveState) -> dict[str, Reading]:
        nominal_hz = self._nominal_hz.get(state.name)
        if nominal_hz is None:
            plan = self._gateway.drive_plan(state.name)
            nominal_hz = plan.nominal_frequency_hz if plan is not None else 50.0
            self._nominal_hz[state.name] = nominal_hz
        return device_readings(state, nominal_hz, outcome=self._outcomes.get(state.name, ("", "")))

    def _update(self, state: DriveState) -> None:
        device = state.name
        readings = self._readings_of(state)
        before = self._readings.get(device)
        was_online = self._online.get(device, False)
        self._readings[device] = readings
        self._online[device] = state.online
        self._buses[device] = state.bus
        now_ms = self._now_ms()
        if not state.online:
            if was_online:
                self._apply(self.node.device_offline(device, now_ms))
            return
        changes = changed(before or {}, readings)
        number = (
            self.forward.record(state.bus, device, changes, self._clock.wall()) if changes else None
        )
        if not was_online:
            self._apply(self.node.device_online(device, readings, now_ms), number)
        elif changes:
            self._apply(self.node.device_data(device, changes, readings, now_ms), number)

    def _answer(self, device: str, result: CommandResult) -> None:
        """A DCMD write ended: its outcome and reason go out as the drive's metrics."""
        outcome = (result.outcome.value, result.reason or "")
        self._outcomes[device] = outcome
        readings = self._readings.get(device)
        if readings is None:
            return
        at_ms = self._now_ms()
        changes = {
            LAST_OUTCOME: Reading(DataType.STRING, outcome[0], at_ms=at_ms),
            LAST_REASON: Reading(DataType.STRING, outcome[1], at_ms=at_ms),
        }
        readings.update(changes)
        if not self._online.get(device, False):
            return
        number = self.forward.record(self._buses[device], device, changes, self._clock.wall())
        self._apply(self.node.device_data(device, changes, readings, at_ms), number)

    def _devices(self) -> dict[str, dict[str, Reading]]:
        """Every online drive's readings, to be born."""
        return {d: r for d, r in self._readings.items() if self._online.get(d, False)}

    def _now_ms(self) -> int:
        return round(self._clock.wall() * 1000)

    def _apply(
        self, effects: list[Effect], number: int | None = None, *, history: bool = False
    ) -> None:
        """Queue ``effects`` in order; ``number``: the change they carry (or told by birth)."""
        if self._client is None:
            return
        now = self._clock.now()
        if not effects and number is not None and self.node.phase is Phase.ONLINE:
            self._queue.append((None, number, now, False))  # told by no message: in its turn
        for at, effect in enumerate(effects):
            self._queue.append((effect, number if at == len(effects) - 1 else None, now, history))
        self._history_out += len(effects) if history else 0
        if self._queue:
            self._idle.clear()
            self._queued.set()

    def _node_effects(self, effects: list[Effect] | None) -> None:
        """Effects of the node's own rules (births, deaths); the store hears of a birth."""
        self._apply(effects or [])
        online = self.node.phase is Phase.ONLINE
        if online and not self._was_online:
            self.forward.session_live()
        elif self._was_online and not online:
            self.forward.session_ended()
        self._was_online = online

    # -- the connection -------------------------------------------------------------------

    async def _connect_forever(self) -> None:
        attempt = 0
        while True:
            sessions = self.connections
            try:
                await self._session()
            except* _Leave as group:
                log.info("sparkplug.left", reason=str(group.exceptions[0]))
            except* aiomqtt.MqttError as group:
                error = str(group.exceptions[0])
                if self.connections > sessions:
                    log.warning("sparkplug.disconnected", error=error)
                else:
                    log.warning("sparkplug.connect_failed", error=error, attempt=attempt + 1)
            except* Exception:  # a bug must not end the edge node for good: log, back off
                log.exception("sparkplug.session_failed")
            if self.connections > sessions:
                attempt = 0
            settings = self._settings
            delay = min(settings.reconnect_max_s, settings.reconnect_min_s * 2**attempt)
            attempt += 1
            await self._clock.sleep(delay * self._rng.uniform(0.5, 1.0))

    def _client_for(self, bd_seq: int) -> aiomqtt.Client:
        settings = self._settings
        will = self.node.will(bd_seq, self._now_ms())
        return aiomqtt.Client(
            self._host,
            self._port,
            identifier=self.client_id,
            username=settings.username,
            password=settings.password,
            will=aiomqtt.Will(will.topic, will.payload, qos=1, retain=False),
            clean_session=True,
            keepalive=settings.keepalive_s,
            tls_context=self._tls,
            socket_options=((socket.IPPROTO_TCP, socket.TCP_NODELAY, 1),),
        )

    async def _session(self) -> None:
        # A new CONNECT carries the next bdSeq, kept on disk before the broker sees it.
        self._bd_seq = await asyncio.to_thread(next_bd_seq, self._bd_path, self._bd_seq)
        bd_seq = self._bd_seq
        client = self._client_for(bd_seq)
        client.pending_calls_threshold = MAX_QUEUED
        async with client:
            for topic in self.node.subscriptions():
                granted = await client.subscribe(topic, qos=1)
                if any(_refused(code) for code in granted):  # the broker's ACL says no
                    log.error("sparkplug.subscribe_refused", topic=topic)
            self.connections += 1
            self._client = client
            self._history_out, self._lag_s = 0, 0.0
            self.connected.set()
            log.info("sparkplug.connected", host=self._host, port=self._port, bd_seq=bd_seq)
            try:
                self._node_effects(
                    self.node.connected(bd_seq, self._clock.now(), self._now_ms(), self._devices())
                )
                async with asyncio.TaskGroup() as group:
                    group.create_task(self._send(client, group), name="sparkplug.sender")
                    group.create_task(self._barriers(client), name="sparkplug.barrier")
                    group.create_task(self._drain(), name="sparkplug.drain")
                    async for message in client.messages:
                        self._receive(message)
            finally:
                self._client = None
                self.connected.clear()
                self._queue.clear()
                self._queued.clear()
                self._idle.set()
                self.node.disconnected()
                self.forward.session_ended()
                self._was_online = False

    def _receive(self, message: aiomqtt.Message) -> None:
        payload = message.payload
        data = bytes(payload) if isinstance(payload, bytes | bytearray) else b""
        topic = message.topic.value
        now, now_ms = self._clock.now(), self._now_ms()
        if topic == self.node.state_topic:
            effects = self.node.host_state(data, now, now_ms, self._devices())
            if effects is None:
                log.warning("sparkplug.state_invalid", topic=topic)
            self._node_effects(effects)
            return
        device = self.node.command_device(topic)
        if device == "":
            metrics = command_metrics(data)
            births = self.node.births
            self._node_effects(self.node.node_command(metrics or (), now, now_ms, self._devices()))
            if self.node.births > births:
                log.info("sparkplug.rebirth", births=self.node.births)
        elif device is not None:
            self._desk.receive(device, command_metrics(data))

    async def _send(self, client: aiomqtt.Client, group: asyncio.TaskGroup) -> None:
        # Up to MAX_IN_FLIGHT publications wait for their writing at once: one at a time, a
        # busy loop carried about a thousand a second, and live data queued behind itself.
        # Each is started in the queue's order (aiomqtt hands a message to paho before its
        # first await), so the wire keeps the order seq was given in.
        queue = self._queue
        slots = asyncio.Semaphore(MAX_IN_FLIGHT)
        last: asyncio.Task[None] | None = None
        while True:
            if not queue:
                self._idle.set()
                self._queued.clear()
                await self._queued.wait()
                continue
            if len(queue) > MAX_QUEUED:  # the broker takes less than we make: start afresh
                raise aiomqtt.MqttError(f"more than {MAX_QUEUED} messages wait for the broker")
            effect, number, queued_at, history = queue.popleft()
            if isinstance(effect, Disconnect):
                if last is not None:  # the NDEATH before it is out first
                    await asyncio.wait([last])
                raise _Leave(effect.reason)
            await slots.acquire()
            last = group.create_task(
                self._publish(client, effect, (number, queued_at, history), last, slots),
                name="sparkplug.publish",
            )

    async def _publish(
        self,
        client: aiomqtt.Client,
        effect: Publish | None,
        told: tuple[int | None, float, bool],
        before: asyncio.Task[None] | None,
        slots: asyncio.Semaphore,
    ) -> None:
        """Publish ``effect``; once it and all before it are written, count its change sent.

        ``told``: the number of the change it carries, when it was queued, whether history.
        """
        number, queued_at, history = told
        try:
            if effect is not None:
                if history:
                    self.history_messages += 1
                await client.publish(effect.topic, effect.payload, qos=effect.qos)
                if not history:  # how late live data is: the drain's measure
                    self._lag_s = max(self._lag_s, self._clock.now() - queued_at)
            if before is not None and not before.done():
                await asyncio.wait([before])
        finally:
            slots.release()
            if history and effect is not None:
                self._history_out -= 1
                self._history_written.set()
        if number is not None:
            self._sent_n = max(self._sent_n, number)

    @property
    def history_rate(self) -> float:
        """The drain's pace now, in changes per second (lower while live data was late)."""
        return self._pace.rate

    @property
    def published_through(self) -> int:
        """The last change number handed to the connection (not yet proven received)."""
        return self._sent_n

    async def _barrier(self, client: aiomqtt.Client) -> None:
        """Wait until the broker has taken in everything published so far on ``client``."""
        self.barriers += 1
        await client.unsubscribe(f"fcmaster/barrier/{self.client_id}")
        self.barriers_answered += 1

    async def _barriers(self, client: aiomqtt.Client) -> None:
        confirmed = 0
        while True:
            await self._clock.sleep(BARRIER_S)
            through = self._sent_n
            if through > confirmed:
                await self._barrier(client)
                self.forward.confirm(through)
                confirmed = through

    async def _drain(self) -> None:
        """Stored history out, oldest first, a message at a time while live data keeps up."""
        pace = self._pace
        while True:
            if self.node.phase is not Phase.ONLINE:
                await self._clock.sleep(DRAIN_IDLE_S)
                continue
            changes, through = await self.forward.backlog()
            if not changes:
                await self.forward.settle(through)
                await self._clock.sleep(DRAIN_IDLE_S)
                continue
            for device, history, rows in _messages(changes):
                await self._live_first(pace)
                if not self.node.is_born(device):
                    self.forward.unborn += rows
                    continue
                effects = self.node.device_history(device, history, self._now_ms())
                self._apply(effects, history=True)
                self.forward.replayed += rows
                await self._paced(rows / pace.rate)
            await self._idle.wait()
            client = self._client
            if client is None:
                return
            await self._barrier(client)
            await self.forward.settle(through)

    async def _live_first(self, pace: _Pace) -> None:
        """Wait until history may go without delaying live data; ``pace`` told what it saw.

        History goes when no live message is queued, the hub holds nothing the pump has not
        read, the last history message has been written, and no live message since the last
        look took longer than :data:`LIVE_LAG_S` (nor the loop as long to wake the drain).
        """
        subscription = self._subscription
        yielded = False
        while True:
            await self._idle.wait()
            if self._history_out > 0:
                self._history_written.clear()
                await self._history_written.wait()
                continue
            if subscription is not None and subscription.pending and not yielded:
                yielded = True  # the pump's turn first: what it reads is queued ahead
                await asyncio.sleep(0)
                continue
            lag, self._lag_s = self._lag_s, 0.0
            if lag <= LIVE_LAG_S:
                pace.keeping_up()
                return
            pace.behind()
            self.history_held += 1
            await self._clock.sleep(min(lag, 1.0))  # live data catches up meanwhile

    async def _paced(self, seconds: float) -> None:
        """The drain's pause between messages; a loop that wakes it late counts as lag."""
        started = self._clock.now()
        await self._clock.sleep(seconds)
        self._lag_s = max(self._lag_s, self._clock.now() - started - seconds)


class _Pace:
    """The drain's rows per second: halved while live data is late, grown back while not."""

    def __init__(self) -> None:
        self.rate = HISTORY_ROWS_PER_S

    def behind(self) -> None:
        self.rate = max(HISTORY_MIN_ROWS_PER_S, self.rate / 2)

    def keeping_up(self) -> None:
        self.rate = min(HISTORY_ROWS_PER_S, self.rate * 1.1)


def _messages(changes: list[Change]) -> list[tuple[str, list[tuple[str, Reading]], int]]:
    """Changes as history messages: by device, in the order made, a few at a time.

    Each: the device, the readings of at most :data:`HISTORY_MESSAGE_ROWS` changes, and how
    many changes they are.
    """
    by_device: dict[str, list[Change]] = {}
    for change in changes:
        by_device.setdefault(change.device, []).append(change)
    messages = []
    for device, made in by_device.items():
        for start in range(0, len(made), HISTORY_MESSAGE_ROWS):
            part = made[start : start + HISTORY_MESSAGE_ROWS]
            messages.append((device, [r for c in part for r in c.readings], len(part)))
    return messages


def _report_crash(task: asyncio.Task[None]) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.error("sparkplug.task_crashed", task=task.get_name(), exc_info=task.exception())
