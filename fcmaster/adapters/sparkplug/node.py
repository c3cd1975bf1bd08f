"""The edge node's session rules (Sparkplug 3.0), sans-I/O: what to publish, and when.

Theory of operation
-------------------
One :class:`EdgeNode` follows one MQTT session after another. It is told what happens — the
session connected (with the ``bdSeq`` its Will carries), the primary host's STATE arrived, a
Rebirth was asked for, a drive came online, changed or went offline, the session ended — and
answers with effects: :class:`Publish` (topic, payload, QoS) and :class:`Disconnect`. The
adapter carries them out in order; nothing here touches the broker or a clock.

Phases: ``OFFLINE`` (no session) → ``WAITING`` (connected and subscribed, waiting for the
primary host's STATE ``online``; skipped when no primary host is configured) → ``ONLINE``
(NBIRTH and the DBIRTHs published). Rules that live only here:

* ``bdSeq`` is the Will's: the NBIRTH of a session carries the number its Will (NDEATH)
  carries, and so does the NBIRTH of a Rebirth in the same session.
* ``seq`` is 0 in NBIRTH and goes up by one, modulo 256, on every NBIRTH, DBIRTH, DDATA and
  DDEATH after it in the session; NDEATH has none.
* A device is born (DBIRTH) with every metric it will ever publish; a DDATA carrying a
  metric the device was not born with (a drive's value read for the first time) is sent as a
  new DBIRTH instead. History for a metric not born in this session is left out.
* STATE with a timestamp older than the last one seen is stale and ignored. ``online`` while
  waiting: births. ``offline`` while online: NDEATH, then disconnect (the adapter then
  reconnects, with a new ``bdSeq``, and waits again).
* A Rebirth (NCMD ``Node Control/Rebirth`` true) sooner than ``rebirth_min_s`` after the
  last one honoured is ignored: a host in a loop must not make a storm of births. The first
  is always honoured, however soon after the session's own births.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum

from fcmaster.adapters.sparkplug.metrics import Reading, birth_metrics, data_metrics
from fcmaster.adapters.sparkplug.payload import (
    DataType,
    Metric,
    Payload,
    decode_payload,
    encode_payload,
)
from fcmaster.errors import ProtocolError

__all__ = [
    "BD_SEQ",
    "NAMESPACE",
    "REBIRTH",
    "Disconnect",
    "EdgeNode",
    "Effect",
    "Phase",
    "Publish",
    "command_metrics",
    "parse_state",
]

NAMESPACE = "spBv1.0"
BD_SEQ = "bdSeq"
REBIRTH = "Node Control/Rebirth"

Devices = Mapping[str, Mapping[str, Reading]]  # every online drive's readings, by device id


class Phase(Enum):
    """Where the session is (see the module docstring)."""

    OFFLINE = "offline"
    WAITING = "waiting"
    ONLINE = "online"


@dataclass(slots=True, frozen=True)
class Publish:
    """Publish ``payload`` on ``topic``."""

    topic: str
    payload: bytes
    qos: int = 0


@dataclass(slots=True, frozen=True)
class Disconnect:
    """End the session (after what came before it is published)."""

    reason: str


Effect = Publish | Disconnect


def parse_state(payload: bytes) -> tuple[bool, int] | None:
    """A Sparkplug 3.0 STATE payload as ``(online, timestamp)``; None when it is not one."""
    try:
        data = json.loads(payload)
    except (ValueError, RecursionError):
        return None
    if not isinstance(data, dict):
        return None
    online, timestamp = data.get("online"), data.get("timestamp")
    if not isinstance(online, bool) or isinstance(timestamp, bool):
        return None
    if not isinstance(timestamp, int):
        return None
    return online, timestamp


class EdgeNode:
    """One edge node's Sparkplug session logic (see the module docstring)."""

    def __init__(
        self,
        *,
        group_id: str,
        edge_node_id: str,
        primary_host_id: str | None = None,
        rebirth_min_s: float = 5.0,
    ) -> None:
        self.group_id = group_id
        self.edge_node_id = edge_node_id
        self.primary_host_id = primary_host_id
        self.rebirth_min_s = rebirth_min_s
        self.phase = Phase.OFFLINE
        self.bd_seq = 0
        self._seq = 0
        self._host_at: int | None = None  # timestamp of the last STATE taken
        self._born: dict[str, dict[str, DataType]] = {}
        self._rebirth_at: float | None = None  # when a Rebirth was last honoured
        self.births = 0  # NBIRTHs published, in every session
        self.rebirths_ignored = 0

    # -- topics ---------------------------------------------------------------------------

    def node_topic(self, kind: str) -> str:
        """``spBv1.0/<group>/<kind>/<edge node>``."""
        return f"{NAMESPACE}/{self.group_id}/{kind}/{self.edge_node_id}"

    def device_topic(self, kind: str, device: str) -> str:
        """``spBv1.0/<group>/<kind>/<edge node>/<device>``."""
        return f"{self.node_topic(kind)}/{device}"

    @property
    def state_topic(self) -> str | None:
        """The primary host's STATE topic (3.0: ``spBv1.0/STATE/<host id>``), if one is set."""
        if self.primary_host_id is None:
            return None
        return f"{NAMESPACE}/STATE/{self.primary_host_id}"

    def subscriptions(self) -> list[str]:
        """What a session subscribes to before anything is born: commands, the host's STATE."""
        topics = [self.node_topic("NCMD"), self.device_topic("DCMD", "+")]
        if self.state_topic is not None:
            topics.append(self.state_topic)
        return topics

    def command_device(self, topic: str) -> str | None:
        """The device a DCMD topic names; ``""`` for this node's NCMD; None: not ours."""
        if topic == self.node_topic("NCMD"):
            return ""
        prefix = self.node_topic("DCMD") + "/"
        if topic.startswith(prefix) and "/" not in topic[len(prefix) :]:
            return topic[len(prefix) :] or None
        return None

    # -- the session ----------------------------------------------------------------------

    def will(self, bd_seq: int, now_ms: int) -> Publish:
        """The NDEATH to leave as the session's Will (QoS 1), carrying ``bd_seq``."""
        return self._death(bd_seq, now_ms)

    def _death(self, bd_seq: int, now_ms: int) -> Publish:
        metric = Metric(name=BD_SEQ, datatype=DataType.INT64, value=bd_seq, timestamp=now_ms)
        payload = Payload(timestamp=now_ms, metrics=(metric,))
        return Publish(self.node_topic("NDEATH"), encode_payload(payload), qos=1)

    def connected(self, bd_seq: int, now: float, now_ms: int, devices: Devices) -> list[Effect]:
        """A session is up and subscribed, under a Will carrying ``bd_seq``."""
        self.bd_seq = bd_seq
        self._born.clear()
        self.phase = Phase.WAITING
        if self.primary_host_id is None:
            return self._births(now_ms, devices)
        return []

    def disconnected(self) -> None:
        """The session ended (whatever the reason): nothing is born any more."""
        self.phase = Phase.OFFLINE
        self._born.clear()

    def death(self, now_ms: int) -> Publish:
        """The NDEATH to publish before leaving on purpose (shutdown, host offline)."""
        return self._death(self.bd_seq, now_ms)

    def host_state(
        self, payload: bytes, now: float, now_ms: int, devices: Devices
    ) -> list[Effect] | None:
        """The primary host's STATE arrived; None when the payload is not a STATE."""
        parsed = parse_state(payload)
        if parsed is None:
            return None
        online, timestamp = parsed
        if self._host_at is not None and timestamp < self._host_at:
            return []  # an older STATE than one already taken: stale
        self._host_at = timestamp
        if online and self.phase is Phase.WAITING:
            return self._births(now_ms, devices)
        if not online and self.phase is Phase.ONLINE:
            self.phase = Phase.WAITING
            return [self.death(now_ms), Disconnect("the primary host went offline")]
        return []

    def node_command(
        self, metrics: tuple[Metric, ...], now: float, now_ms: int, devices: Devices
    ) -> list[Effect]:
        """An NCMD's metrics: a Rebirth is honoured (rate-limited), anything else ignored."""
        asked = any(m.name == REBIRTH and m.value is True for m in metrics)
        if not asked or self.phase is not Phase.ONLINE:
            return []
        if self._rebirth_at is not None and now - self._rebirth_at < self.rebirth_min_s:
            self.rebirths_ignored += 1
            return []
        self._rebirth_at = now
        return self._births(now_ms, devices)

    def _births(self, now_ms: int, devices: Devices) -> list[Effect]:
        self.phase = Phase.ONLINE
        self.births += 1
        self._seq = 0
        self._born.clear()
        metrics = (
            Metric(name=BD_SEQ, datatype=DataType.INT64, value=self.bd_seq, timestamp=now_ms),
            Metric(name=REBIRTH, datatype=DataType.BOOLEAN, value=False, timestamp=now_ms),
        )
        effects: list[Effect] = [self._node("NBIRTH", metrics, now_ms)]
        for device, readings in devices.items():
            effects.append(self._device_birth(device, readings, now_ms))
        return effects

    # -- devices --------------------------------------------------------------------------

    def is_born(self, device: str) -> bool:
        """Whether ``device`` had its DBIRTH in this session (and no DDEATH since)."""
        return device in self._born

    def device_online(
        self, device: str, readings: Mapping[str, Reading], now_ms: int
    ) -> list[Effect]:
        """A drive came online: its DBIRTH, if the node is online."""
        if self.phase is not Phase.ONLINE:
            return []
        return [self._device_birth(device, readings, now_ms)]

    def device_offline(self, device: str, now_ms: int) -> list[Effect]:
        """A drive went offline: its DDEATH, if it was born."""
        if self._born.pop(device, None) is None or self.phase is not Phase.ONLINE:
            return []
        payload = Payload(timestamp=now_ms, seq=self._next_seq())
        return [Publish(self.device_topic("DDEATH", device), encode_payload(payload))]

    def device_data(
        self,
        device: str,
        changes: Mapping[str, Reading],
        readings: Mapping[str, Reading],
        now_ms: int,
    ) -> list[Effect]:
        """Live ``changes`` of a born drive (``readings``: all of them, for a new DBIRTH)."""
        born = self._born.get(device)
        if self.phase is not Phase.ONLINE or born is None or not changes:
            return []
        if any(born.get(name) != r.datatype for name, r in changes.items()):
            return [self._device_birth(device, readings, now_ms)]
        return [self._device_data(device, data_metrics(dict(changes)), now_ms)]

    def device_history(
        self, device: str, history: list[tuple[str, Reading]], now_ms: int
    ) -> list[Effect]:
        """Stored readings, oldest first, as one DDATA of historical metrics.

        Only metrics the device was born with in this session, with the type it was born
        with, can go: a host would refuse the whole message otherwise.
        """
        born = self._born.get(device)
        if self.phase is not Phase.ONLINE or born is None:
            return []
        metrics = tuple(
            metric
            for name, reading in history
            if born.get(name) == reading.datatype
            for metric in data_metrics({name: reading}, historical=True)
        )
        if not metrics:
            return []
        return [self._device_data(device, metrics, now_ms)]

    def _device_birth(self, device: str, readings: Mapping[str, Reading], now_ms: int) -> Publish:
        self._born[device] = {name: r.datatype for name, r in readings.items()}
        payload = Payload(
            timestamp=now_ms, metrics=birth_metrics(dict(readings)), seq=self._next_seq()
        )
        return Publish(self.device_topic("DBIRTH", device), encode_payload(payload))

    def _device_data(self, device: str, metrics: tuple[Metric, ...], now_ms: int) -> Publish:
        payload = Payload(timestamp=now_ms, metrics=metrics, seq=self._next_seq())
        return Publish(self.device_topic("DDATA", device), encode_payload(payload))

    def _node(self, kind: str, metrics: tuple[Metric, ...], now_ms: int) -> Publish:
        payload = Payload(timestamp=now_ms, metrics=metrics, seq=self._next_seq())
        return Publish(self.node_topic(kind), encode_payload(payload))

    def _next_seq(self) -> int:
        seq = self._seq
        self._seq = (seq + 1) % 256
        return seq


def command_metrics(payload: bytes) -> tuple[Metric, ...] | None:
    """The metrics of an NCMD or DCMD payload; None when it cannot be decoded."""
    try:
        return decode_payload(payload).metrics
    except ProtocolError:
        return None
