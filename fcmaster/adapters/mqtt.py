"""The MQTT bridge: drive state out to the plant, commands in (DESIGN.md "MQTT").

Theory of operation
-------------------
The bridge is a hub subscriber and a command source, and it never makes the bus wait for the
broker. Its parts:

* the **pump** reads the hub subscription (snapshots conflate there, events are bounded) and
  files what it reads in the :class:`~fcmaster.adapters.mqtt_outbox.Outbox`: a drive's
  state when it changed beyond the deadband (see ``mqtt_topics``), its availability, its
  events, discovery configs for values seen for the first time. It never touches the broker.
* the **heartbeat** files every drive's current state each ``heartbeat_s``, changed or not.
* the **connection loop** connects (TCP or TLS, with the will ``offline`` retained on the
  status topic), subscribes to ``{base}/{bus}/+/command`` for each of its own lines (QoS 1),
  marks every retained topic for republication (status ``online``, discovery, availability,
  state), and runs a session: a sender draining the outbox and a receiver for commands. When
  the connection fails it waits — exponential from ``reconnect_min_s`` to
  ``reconnect_max_s``, with jitter so that a fleet of gateways does not reconnect in step —
  and starts again.
* the receiver hands each command to the
  :class:`~fcmaster.adapters.mqtt_commands.CommandDesk`, which answers invalid ones at once
  and runs each valid one in a task of its own; every result goes to the outbox, which
  keeps it across reconnects until the broker has acknowledged it.

Commands are off unless ``mqtt.commands: true`` (then answered ``not_allowed``); when on,
each payload carries ``"token"``, an operator token of ``http.tokens`` whose name is the
audit's actor, unless ``mqtt.trust_broker: true`` leaves it to the broker's ACLs (the actor is
then the bridge's own ``mqtt:{client_id}``).

The session outlives an absence: the bridge subscribes at QoS 1 with ``clean_session``
off under a client id that stays the same (``mqtt.client_id``, or one made of the host name,
the base topic and the lines), so commands published while it reconnects (a broker restart
with persistence, a network blip) wait at the broker and are carried out when it is back,
each with its result. A restart of the gateway itself leaves nothing to replay: before its
first session the bridge connects once with a clean session, which drops whatever was
queued for it while it was not running — such a command may no longer be wanted; its
sender saw no result. A command that must not run late at all is best published with a
message expiry (MQTT 5), which the broker honours while it waits.

Shutdown: commands still running get a bounded grace, then end ``cancelled``; the drives'
availability and the gateway's status turn ``offline``; the outbox is flushed (bounded, and
only when connected), and the client disconnects cleanly.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import random
import socket
import ssl
from collections.abc import Iterable
from types import TracebackType
from typing import Any
from urllib.parse import urlsplit

import aiomqtt
import structlog
from paho.mqtt.reasoncodes import ReasonCode

from fcmaster.adapters.auth import Authenticator, Role
from fcmaster.adapters.discovery import Discovery
from fcmaster.adapters.gateway import Gateway
from fcmaster.adapters.mqtt_commands import CommandDesk, CommandPolicy
from fcmaster.adapters.mqtt_outbox import Outbox, Outgoing
from fcmaster.adapters.mqtt_topics import (
    OFFLINE,
    ONLINE,
    Topics,
    encode,
    event_payload,
    is_significant,
)
from fcmaster.adapters.settings import MqttSettings, SparkplugSettings
from fcmaster.errors import ConfigError
from fcmaster.hub import EventsDropped, Subscription
from fcmaster.state import (
    AvailabilityChanged,
    ConditionChanged,
    DriveState,
    DriveUpdated,
    rfc3339,
)

log = structlog.get_logger("fcmaster.adapters.mqtt")

MAX_IN_FLIGHT = 64  # publications awaiting the broker's acknowledgement at once
COMMAND_GRACE_S = 5.0  # at shutdown, how long running commands may take to end
FLUSH_S = 2.0  # at shutdown, how long the last messages may take to reach the broker


class MqttAdapter:
    """The MQTT bridge for one gateway; an async context manager (see the module docstring)."""

    def __init__(
        self,
        settings: MqttSettings,
        gateway: Gateway,
        *,
        demo: bool = False,
        tokens: Iterable[tuple[str, str, str]] = (),
    ) -> None:
        """Bridge ``gateway`` to the broker ``settings`` names; ConfigError for bad settings.

        ``demo`` changes nothing here. The gateway's clock paces the heartbeat and the
        reconnect backoff and stamps events. ``tokens`` are ``http.tokens`` as ``(name, role,
        secret)``: with ``mqtt.commands`` on, a command carries one of the operator ones.
        """
        self._settings = settings
        self._gateway = gateway
        self._clock = gateway.clock
        self._topics = Topics(settings.base_topic, settings.status_topic)
        self._buses = [line.name for line in gateway.lines()]
        # The same id from one start to the next, so the broker keeps one session for us.
        mark = hashlib.sha256("\n".join([settings.base_topic, *self._buses]).encode())
        self.client_id = (
            settings.client_id or f"fcmaster-{socket.gethostname()}-{mark.hexdigest()[:6]}"
        )
        self._stale_session = True  # what the broker kept from before we started
        parts = urlsplit(settings.url)
        self._host = parts.hostname or ""
        self._port = parts.port or (8883 if parts.scheme == "mqtts" else 1883)
        self._tls = _tls_context(settings) if parts.scheme == "mqtts" else None
        for name in [*self._buses, *(state.name for state in gateway.fleet.snapshot())]:
            if not name or set(name) & {"/", "+", "#"}:
                raise ConfigError([("mqtt", f"{name!r} cannot be an MQTT topic level")])
        self._discovery = (
            Discovery(
                self._topics,
                settings.discovery_prefix,
                controls=settings.commands and settings.trust_broker,
            )
            if settings.discovery
            else None
        )
        self._discovered: set[tuple[str, str]] = set()
        self._outbox = Outbox()
        self._sent_states: dict[str, DriveState] = {}
        self._nominal_hz: dict[str, float] = {}
        self.actor = f"mqtt:{self.client_id}"
        auth = Authenticator(
            [(name, Role[role.upper()], secret) for name, role, secret in tokens],
            anonymous=False,
        )
        self._desk = CommandDesk(
            gateway,
            self._topics,
            self._outbox,
            actor=self.actor,
            policy=CommandPolicy(
                enabled=settings.commands, auth=None if settings.trust_broker else auth
            ),
        )
        self._tasks: list[asyncio.Task[None]] = []
        self._subscription: Subscription | None = None
        self._rng = random.Random()
        self._entered = False
        self._events_dropped = 0
        self.connected = asyncio.Event()
        self.connections = 0  # sessions started so far

    # -- lifecycle ------------------------------------------------------------------------

    async def __aenter__(self) -> MqttAdapter:
        """Start bridging: file every drive's state, then connect in the background."""
        if self._entered:
            raise RuntimeError("MqttAdapter is not re-entrant")
        self._entered = True
        self._subscription = self._gateway.hub.subscribe(
            kinds=(DriveUpdated, AvailabilityChanged, ConditionChanged)
        )
        self._outbox.retain(self._topics.status, ONLINE)
        for state in self._gateway.fleet.snapshot():
            self._file_state(state, force=True)
        self._tasks = [
            asyncio.create_task(self._pump(self._subscription), name="mqtt.pump"),
            asyncio.create_task(self._heartbeat(), name="mqtt.heartbeat"),
            asyncio.create_task(self._connect_forever(), name="mqtt.connection"),
        ]
        for task in self._tasks:
            task.add_done_callback(_report_crash)
        log.info("mqtt.started", url=self._settings.url, client_id=self.client_id)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        """Stop: end the commands, say offline, flush (bounded), disconnect."""
        try:
            await self._desk.close(COMMAND_GRACE_S)
            pump, heartbeat, connection = self._tasks
            await _cancel(pump, heartbeat)
            for state in self._gateway.fleet.snapshot():
                self._outbox.retain(self._topics.availability(state.bus, state.name), OFFLINE)
            self._outbox.retain(self._topics.status, OFFLINE)
            if self.connected.is_set():
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(FLUSH_S):
                        await self._outbox.flushed()
            await _cancel(connection, grace_s=FLUSH_S)
        finally:
            if self._subscription is not None:
                self._subscription.close()
            self._entered = False
            log.info("mqtt.stopped", unsent=self._outbox.pending + self._outbox.in_flight)

    # -- hub → outbox ---------------------------------------------------------------------

    async def _pump(self, subscription: Subscription) -> None:
        async for item in subscription:
            if isinstance(item, DriveUpdated):
                self._file_state(item.state)
            elif isinstance(item, AvailabilityChanged):
                event = "online" if item.online else "offline"
                self._file_event(item.bus, item.drive, event)
            elif isinstance(item, ConditionChanged):
                event = f"{item.kind}_{'raised' if item.active else 'cleared'}"
                self._file_event(item.bus, item.drive, event, code=item.code, text=item.text)
            elif isinstance(item, EventsDropped):
                log.warning("mqtt.events_dropped", count=item.count, where="hub")
            if self._outbox.events_dropped > self._events_dropped:
                log.warning(
                    "mqtt.events_dropped",
                    count=self._outbox.events_dropped - self._events_dropped,
                    where="outbox",
                )
                self._events_dropped = self._outbox.events_dropped

    async def _heartbeat(self) -> None:
        while True:
            await self._clock.sleep(self._settings.heartbeat_s)
            for state in self._gateway.fleet.snapshot():
                self._file_state(state, force=True)

    def _file_state(self, state: DriveState, *, force: bool = False) -> None:
        sent = self._sent_states.get(state.key)
        if force or sent is None or self._significant(sent, state):
            self._sent_states[state.key] = state
            self._outbox.retain(
                self._topics.state(state.bus, state.name), encode(state.to_json()), force=force
            )
        self._outbox.retain(
            self._topics.availability(state.bus, state.name), ONLINE if state.online else OFFLINE
        )
        if self._discovery is not None:
            self._file_discovery(self._discovery, state)

    def _significant(self, sent: DriveState, state: DriveState) -> bool:
        nominal_hz = self._nominal_hz.get(state.name)
        if nominal_hz is None:
            plan = self._gateway.drive_plan(state.name)
            nominal_hz = self._nominal_hz[state.name] = (
                plan.nominal_frequency_hz if plan is not None else 50.0
            )
        return is_significant(
            sent, state, deadband_pct=self._settings.deadband_pct, nominal_frequency_hz=nominal_hz
        )

    def _file_discovery(self, discovery: Discovery, state: DriveState) -> None:
        if (state.key, "") not in self._discovered:
            self._discovered.add((state.key, ""))
            for topic, payload in discovery.drive(state, self._gateway.drive_plan(state.name)):
                self._outbox.retain(topic, payload)
        for name, measured in state.values.items():
            if (state.key, name) not in self._discovered:
                self._discovered.add((state.key, name))
                self._outbox.retain(*discovery.value(state, name, measured.unit))

    def _file_event(self, bus: str, drive: str, event: str, **facts: Any) -> None:
        at = rfc3339(self._clock.wall())
        self._outbox.event(
            self._topics.event(bus, drive), event_payload(event, bus, drive, at, **facts)
        )

    # -- the connection -------------------------------------------------------------------

    async def _connect_forever(self) -> None:
        attempt = 0
        while True:
            sessions = self.connections
            try:
                await self._session()
            except* aiomqtt.MqttError as group:
                error = str(group.exceptions[0])
                if self.connections > sessions:
                    log.warning("mqtt.disconnected", error=error)
                else:
                    log.warning("mqtt.connect_failed", error=error, attempt=attempt + 1)
            except* Exception:  # a bug must not end the bridge for good: log, back off, retry
                log.exception("mqtt.session_failed")
            if self.connections > sessions:
                attempt = 0
            delay = min(self._settings.reconnect_max_s, self._settings.reconnect_min_s * 2**attempt)
            attempt += 1
            await self._clock.sleep(delay * self._rng.uniform(0.5, 1.0))

    def _client(self, *, clean: bool = False) -> aiomqtt.Client:
        settings = self._settings
        client = aiomqtt.Client(
            self._host,
            self._port,
            identifier=self.client_id,
            username=settings.username,
            password=settings.password,
            will=aiomqtt.Will(self._topics.status, OFFLINE, qos=1, retain=True),
            # Commands for us wait at the broker while we reconnect (see the module docstring).
            clean_session=clean,
            keepalive=settings.keepalive_s,
            tls_context=self._tls,
            # small packets (a PUBACK, then the result) must not wait for a delayed ACK
            socket_options=((socket.IPPROTO_TCP, socket.TCP_NODELAY, 1),),
        )
        client.pending_calls_threshold = MAX_IN_FLIGHT + 1  # it warns past this many
        return client

    async def _session(self) -> None:
        if self._stale_session:  # queued before we started: not ours to carry out
            async with self._client(clean=True):
                pass
            self._stale_session = False
        async with self._client() as client:
            for bus in self._buses:
                granted = await client.subscribe(self._topics.commands(bus), qos=1)
                if any(_refused(code) for code in granted):
                    log.error("mqtt.subscribe_refused", topic=self._topics.commands(bus))
            self.connections += 1
            self._outbox.republish()
            self.connected.set()
            log.info("mqtt.connected", host=self._host, port=self._port, buses=self._buses)
            try:
                async with asyncio.TaskGroup() as group:
                    group.create_task(self._send(client, group), name="mqtt.sender")
                    async for message in client.messages:
                        self._desk.receive(message)
            finally:
                self.connected.clear()
                self._outbox.requeue()

    async def _send(self, client: aiomqtt.Client, group: asyncio.TaskGroup) -> None:
        slots = asyncio.Semaphore(MAX_IN_FLIGHT)
        outbox = self._outbox
        while True:
            await outbox.wait()
            await slots.acquire()
            message = outbox.take()
            if message is None:  # pragma: no cover - nothing else takes from the outbox
                slots.release()
                continue
            group.create_task(self._publish(client, message, slots), name="mqtt.publish")

    async def _publish(
        self, client: aiomqtt.Client, message: Outgoing, slots: asyncio.Semaphore
    ) -> None:
        try:
            await client.publish(message.topic, message.payload, qos=1, retain=message.retain)
        finally:
            slots.release()
        self._outbox.sent(message)


def _refused(code: int | ReasonCode) -> bool:
    return code.is_failure if isinstance(code, ReasonCode) else code >= 0x80


def _tls_context(
    settings: MqttSettings | SparkplugSettings, section: str = "mqtt"
) -> ssl.SSLContext:
    """A TLS context for mqtts:// with the configured CA, client certificate and key."""
    tls = settings.tls
    try:
        context = ssl.create_default_context(cafile=tls.ca if tls is not None else None)
        if tls is not None and tls.cert is not None:
            context.load_cert_chain(tls.cert, tls.key)
    except (OSError, ssl.SSLError) as exc:
        raise ConfigError([(f"{section}.tls", f"cannot load the certificates: {exc}")]) from exc
    if tls is not None and tls.insecure:
        context.check_hostname = False
        context.verify_mode = ssl.CERT_NONE
    return context


async def _cancel(*tasks: asyncio.Task[None], grace_s: float | None = None) -> None:
    """Cancel ``tasks`` and wait for them, re-raising only our own cancellation.

    With ``grace_s``, a task still busy after that long (a disconnect the broker never
    acknowledges) is cancelled once more.
    """
    for task in tasks:
        task.cancel()
    if grace_s is not None:
        _, late = await asyncio.wait(tasks, timeout=grace_s)
        for task in late:
            task.cancel()
    for task in tasks:
        try:
            await task
        except asyncio.CancelledError:
            current = asyncio.current_task()
            if current is not None and current.cancelling():
                raise
        except Exception:  # already reported by _report_crash
            continue


def _report_crash(task: asyncio.Task[None]) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.error("mqtt.task_crashed", task=task.get_name(), exc_info=task.exception())
