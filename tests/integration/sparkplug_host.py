"""A Sparkplug B 3.0 host application written from the spec, for the edge node's tests.

It subscribes to a group's messages and judges them as a host must: NBIRTH has seq 0 and a
``bdSeq``; every later NBIRTH, DBIRTH, DDATA and DDEATH of the node comes with the next seq
(mod 256); nothing of a device before its DBIRTH, nothing of a node before its NBIRTH; a
DDATA names only metrics its DBIRTH did; an NDEATH counts only when its ``bdSeq`` matches
the NBIRTH's, as a host pairs them (an older Will arriving late is ignored). What breaks a
rule goes in :attr:`SparkplugHost.problems`. It publishes its own STATE (retained, with a
Will of ``online: false``), Rebirth requests and DCMDs.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any

import aiomqtt

from fcmaster.adapters.sparkplug.payload import (
    DataType,
    Metric,
    Payload,
    decode_payload,
    encode_payload,
)
from tests.integration.mosquitto import Broker

NAMESPACE = "spBv1.0"


@dataclass(slots=True)
class Received:
    """One Sparkplug message as the host took it."""

    kind: str  # NBIRTH, DDATA, …
    node: str
    device: str | None
    payload: Payload
    index: int  # its place among every message received
    raw: bytes = b""  # the payload's bytes as they arrived

    def metric(self, name: str) -> Metric:
        """The metric ``name`` (the last one of that name)."""
        found = [m for m in self.payload.metrics if m.name == name]
        assert found, f"no {name!r} in {self.kind} {self.device}: {self.payload}"
        return found[-1]

    def values(self) -> dict[str, Any]:
        """Metric name → value (the last of each name)."""
        return {m.name: m.value for m in self.payload.metrics if m.name is not None}


@dataclass(slots=True)
class NodeView:
    """What the host knows of one edge node."""

    online: bool = False
    bd_seq: int | None = None
    next_seq: int | None = None
    devices: dict[str, set[str]] = field(default_factory=dict)  # born device → metric names


class SparkplugHost:
    """A primary host application on ``group``; async context manager (see the docstring)."""

    def __init__(
        self, broker: Broker, group: str, host_id: str = "scada", *, announce: bool = True
    ) -> None:
        self.broker = broker
        self.group = group
        self.host_id = host_id
        self.announce = announce
        self.received: list[Received] = []
        self.problems: list[str] = []
        self.nodes: dict[str, NodeView] = {}
        self.deaths: list[tuple[int | None, bool]] = []  # (bdSeq, matched the NBIRTH)
        self._arrived = asyncio.Event()
        self._stack = contextlib.AsyncExitStack()
        self.client: aiomqtt.Client | None = None
        self._last_state_ms = 0

    @property
    def state_topic(self) -> str:
        """``spBv1.0/STATE/<host id>``."""
        return f"{NAMESPACE}/STATE/{self.host_id}"

    def _state(self, online: bool) -> bytes:
        # timestamps must increase from one STATE to the next, even within a millisecond
        self._last_state_ms = max(self._last_state_ms + 1, int(time.time() * 1000))
        return json.dumps({"online": online, "timestamp": self._last_state_ms}).encode()

    async def __aenter__(self) -> SparkplugHost:
        will = aiomqtt.Will(self.state_topic, self._state(False), qos=1, retain=True)
        client = aiomqtt.Client(self.broker.host, self.broker.port, will=will)
        self.client = await self._stack.enter_async_context(client)
        await client.subscribe(f"{NAMESPACE}/{self.group}/#", qos=1)
        task = asyncio.create_task(self._collect(client))
        self._stack.push_async_callback(_cancel, task)
        if self.announce:
            await self.online()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self._stack.aclose()

    async def online(self) -> None:
        """Publish STATE online (retained, QoS 1)."""
        await self._publish(self.state_topic, self._state(True), retain=True)

    async def offline(self) -> None:
        """Publish STATE offline (retained, QoS 1), as a host going away on purpose does."""
        await self._publish(self.state_topic, self._state(False), retain=True)

    async def rebirth(self, node: str) -> None:
        """Ask ``node`` for a Rebirth (NCMD ``Node Control/Rebirth`` true)."""
        metric = Metric(name="Node Control/Rebirth", datatype=DataType.BOOLEAN, value=True)
        payload = Payload(timestamp=int(time.time() * 1000), metrics=(metric,))
        await self._publish(f"{NAMESPACE}/{self.group}/NCMD/{node}", encode_payload(payload))

    async def dcmd(self, node: str, device: str, *metrics: Metric) -> None:
        """Write ``metrics`` of ``device`` (a DCMD)."""
        payload = Payload(timestamp=int(time.time() * 1000), metrics=metrics)
        topic = f"{NAMESPACE}/{self.group}/DCMD/{node}/{device}"
        await self._publish(topic, encode_payload(payload))

    async def _publish(self, topic: str, payload: bytes, *, retain: bool = False) -> None:
        assert self.client is not None
        await self.client.publish(topic, payload, qos=1, retain=retain)

    async def _collect(self, client: aiomqtt.Client) -> None:
        with contextlib.suppress(aiomqtt.MqttError):
            async for message in client.messages:
                self._take(message)
                self._arrived.set()

    def _take(self, message: aiomqtt.Message) -> None:
        parts = message.topic.value.split("/")
        if len(parts) < 4 or parts[2] in ("NCMD", "DCMD"):
            return
        kind, node = parts[2], parts[3]
        device = parts[4] if len(parts) > 4 else None
        assert isinstance(message.payload, bytes | bytearray)
        raw = bytes(message.payload)
        payload = decode_payload(raw)
        self.received.append(Received(kind, node, device, payload, len(self.received), raw))
        self._judge(kind, node, device, payload)

    def _judge(self, kind: str, node: str, device: str | None, payload: Payload) -> None:
        view = self.nodes.setdefault(node, NodeView())
        where = f"{kind} {node}/{device or ''} seq={payload.seq}"
        if kind == "NDEATH":
            bd_seq = _bd_seq(payload)
            matched = view.online and bd_seq == view.bd_seq
            self.deaths.append((bd_seq, matched))
            if matched:
                view.online = False
                view.devices.clear()
            return
        if kind == "NBIRTH":
            if payload.seq != 0:
                self.problems.append(f"{where}: NBIRTH seq is not 0")
            view.online, view.bd_seq, view.next_seq = True, _bd_seq(payload), 1
            view.devices.clear()
            return
        if not view.online:
            self.problems.append(f"{where}: before the node's NBIRTH")
            return
        if payload.seq != view.next_seq:
            self.problems.append(f"{where}: expected seq {view.next_seq}")
        view.next_seq = ((payload.seq or 0) + 1) % 256
        if device is None:
            return
        if kind == "DBIRTH":
            view.devices[device] = {m.name for m in payload.metrics if m.name}
        elif device not in view.devices:
            self.problems.append(f"{where}: before the device's DBIRTH")
        elif kind == "DDEATH":
            del view.devices[device]
        elif kind == "DDATA":
            unknown = {m.name for m in payload.metrics} - view.devices[device]
            if unknown:
                self.problems.append(f"{where}: metrics not born: {sorted(map(str, unknown))}")

    def on(self, kind: str, device: str | None = None) -> list[Received]:
        """Messages of ``kind`` (for ``device``) received so far."""
        return [
            r for r in self.received if r.kind == kind and (device is None or r.device == device)
        ]

    async def wait_count(self, kind: str, count: int, *, start: int = 0) -> list[Received]:
        """The first ``count`` messages of ``kind`` from index ``start`` on."""
        while len(found := [r for r in self.received[start:] if r.kind == kind]) < count:
            self._arrived.clear()
            await self._arrived.wait()
        return found[:count]

    async def wait(
        self, kind: str, check: Callable[[Received], bool] | None = None, *, start: int = 0
    ) -> Received:
        """The first message of ``kind`` from index ``start`` on that passes ``check``."""
        index = start
        while True:
            while index < len(self.received):
                received = self.received[index]
                index += 1
                if received.kind == kind and (check is None or check(received)):
                    return received
            self._arrived.clear()
            await self._arrived.wait()


def _bd_seq(payload: Payload) -> int | None:
    found = [m.value for m in payload.metrics if m.name == "bdSeq"]
    value = found[0] if found else None
    return value if isinstance(value, int) else None


async def _cancel(task: asyncio.Task[None]) -> None:
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
