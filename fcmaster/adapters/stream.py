"""The WebSocket event stream: one hub subscription and one sending task per client.

Theory of operation
-------------------
A client connects to ``/api/v1/stream`` (optionally ``?bus=`` and ``?drive=`` to narrow
it), authenticates like any read (``Authorization`` header, or ``?token=`` from browsers),
and is sent a ``snapshot`` of every drive and line, then one message per fleet event (see
:mod:`fcmaster.adapters.messages`). The subscription is opened *before* the snapshot is
taken, so nothing falls between the two.

The bus never waits for a client: the hub files events with the subscription and returns;
this client's own task takes them out and sends them. Each event is serialised once for
all the streams that send it (:class:`EventTexts`), and a stream sends what gathered at
most every :data:`BATCH_S`: between sends its subscription conflates drive states (latest
wins), so a hundred streams cost a hundred sends of each drive's latest state a batch, not
of every reply. A slow client makes its own send wait (the socket's back-pressure), while
its subscription conflates drive states and bounds discrete events, telling the client
with a ``dropped`` message; one that reads nothing at all is dropped by the connection
guard (:mod:`.http_guard`). A second task reads the client's side only to notice a
disconnect at once.

Browsers send ``Origin``; a stream is refused unless the origin is the page's own (same
host) or listed in ``http.cors_origins``, so another site open in the operator's browser
cannot read the fleet through a loopback connection.
"""

from __future__ import annotations

import asyncio
from collections import OrderedDict
from typing import Final
from urllib.parse import urlsplit

import structlog
from starlette.websockets import WebSocket, WebSocketDisconnect

from fcmaster.adapters.auth import Authenticator, AuthError
from fcmaster.adapters.gateway import Gateway
from fcmaster.adapters.messages import event_json
from fcmaster.adapters.middleware import states_json, strict_json
from fcmaster.drive_state import DriveState
from fcmaster.hub import EventsDropped, Subscription
from fcmaster.state import DriveUpdated, Event

log = structlog.get_logger("fcmaster.adapters.http")

POLICY_VIOLATION = 1008
GOING_AWAY = 1001
BATCH_S: Final = 0.1  # a stream sends what gathered at most this often (10 Hz)
TEXTS_KEPT: Final = 1024  # recent events' messages kept for the other streams


class EventTexts:
    """Each event's message, serialised once for every stream that sends it.

    The hub hands every subscription the same event object, so the object's identity is
    the key (the entry holds the object, so its id is not reused while kept). A drive
    update conflated in a subscription is a new object, but the same drive state with the
    same changes: those are keyed by the state's identity and the changed fields.
    """

    def __init__(self, kept: int = TEXTS_KEPT) -> None:
        self._kept = kept
        self._texts: OrderedDict[object, tuple[object, str]] = OrderedDict()
        self.serialised = 0  # events turned into text (the rest were found here)

    def text(self, item: Event | EventsDropped) -> str:
        """``item``'s stream message."""
        if isinstance(item, EventsDropped):  # one stream's own news
            return strict_json(event_json(item))
        pinned: object = item
        key: object = id(item)
        if isinstance(item, DriveUpdated):
            pinned, key = item.state, (id(item.state), item.changed)
        found = self._texts.get(key)
        if found is not None:
            return found[1]
        text = strict_json(event_json(item))
        self.serialised += 1
        self._texts[key] = (pinned, text)
        if len(self._texts) > self._kept:
            self._texts.popitem(last=False)
        return text


class StreamRegistry:
    """The open streams' subscriptions, and the messages they share.

    The adapter ends every open stream at shutdown through it.
    """

    def __init__(self) -> None:
        self._open: set[Subscription] = set()
        self.texts = EventTexts()

    def add(self, subscription: Subscription) -> None:
        """Track an open stream."""
        self._open.add(subscription)

    def discard(self, subscription: Subscription) -> None:
        """Forget a stream that ended."""
        self._open.discard(subscription)

    def close_all(self) -> None:
        """End every open stream (their clients are told the server is going away)."""
        for subscription in list(self._open):
            subscription.close()

    def __len__(self) -> int:
        return len(self._open)


def _origin_allowed(origin: str | None, host: str | None, allowed: tuple[str, ...]) -> bool:
    if origin is None:  # not a browser
        return True
    if origin in allowed:
        return True
    return host is not None and urlsplit(origin).netloc.lower() == host.lower()


def _limits(gateway: Gateway, states: list[DriveState]) -> dict[str, dict[str, float]]:
    """Each drive's configured frequencies, so a page can say a reference's Hz."""
    out: dict[str, dict[str, float]] = {}
    for state in states:
        plan = gateway.drive_plan(state.name)
        if plan is not None:
            out[state.name] = {
                "nominal_frequency_hz": plan.nominal_frequency_hz,
                "min_frequency_hz": plan.min_frequency_hz,
                "max_frequency_hz": plan.max_frequency_hz,
            }
    return out


async def serve_stream(
    websocket: WebSocket,
    gateway: Gateway,
    auth: Authenticator,
    registry: StreamRegistry,
    *,
    cors_origins: tuple[str, ...] = (),
) -> None:
    """Serve one stream client until it leaves or the adapter stops."""
    headers = websocket.headers
    if not _origin_allowed(headers.get("origin"), headers.get("host"), cors_origins):
        await websocket.close(POLICY_VIOLATION, "origin not allowed")
        return
    token = websocket.query_params.get("token")
    authorization = headers.get("authorization") or (f"Bearer {token}" if token else None)
    try:
        principal = auth.authenticate(
            authorization,
            client_host=websocket.client.host if websocket.client else None,
            host_header=headers.get("host"),
        )
    except AuthError as exc:
        await websocket.close(POLICY_VIOLATION, exc.reason)
        return
    bus = websocket.query_params.get("bus") or None
    drive = websocket.query_params.get("drive") or None
    subscription = gateway.hub.subscribe(bus=bus, drive=drive)
    registry.add(subscription)
    try:
        await websocket.accept()
        log.debug("http.stream_opened", actor=principal.name, bus=bus, drive=drive)
        states = [
            s
            for s in gateway.fleet.snapshot()
            if (bus is None or s.bus == bus) and (drive is None or s.name == drive)
        ]
        drives = await states_json(states)
        lines = strict_json(
            [line.to_json() for line in gateway.lines() if bus in (None, line.name)]
        )
        limits = strict_json(_limits(gateway, states))
        await websocket.send_text(
            f'{{"type": "snapshot", "drives": {drives}, "buses": {lines}, "limits": {limits}}}'
        )
        await _serve(websocket, subscription, registry.texts)
    except (WebSocketDisconnect, OSError):
        pass  # the client left while we were sending
    finally:
        subscription.close()
        registry.discard(subscription)
        log.debug("http.stream_closed", actor=principal.name, dropped=subscription.dropped)


async def _serve(websocket: WebSocket, subscription: Subscription, texts: EventTexts) -> None:
    reader = asyncio.create_task(_until_disconnect(websocket), name="http.stream.reader")
    writer = asyncio.create_task(
        _send_events(websocket, subscription, texts), name="http.stream.writer"
    )
    try:
        done, _ = await asyncio.wait((reader, writer), return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in (reader, writer):
            task.cancel()
        await asyncio.gather(reader, writer, return_exceptions=True)
    if writer in done:
        failure = writer.exception()
        if failure is not None and not isinstance(failure, WebSocketDisconnect | OSError):
            raise failure
        if failure is None and reader not in done:  # the subscription ended: we are stopping
            await websocket.close(GOING_AWAY, "fcmaster is stopping")


async def _until_disconnect(websocket: WebSocket) -> None:
    while True:
        message = await websocket.receive()
        if message["type"] == "websocket.disconnect":
            return


async def _send_events(websocket: WebSocket, subscription: Subscription, texts: EventTexts) -> None:
    async for item in subscription:
        await websocket.send_text(texts.text(item))
        if not subscription.pending:  # sent all that gathered: let the next batch gather
            await asyncio.sleep(BATCH_S)
