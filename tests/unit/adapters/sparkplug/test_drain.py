"""The drain of stored history beside live data, on a connection the test holds in its hand.

The adapter runs whole (pump, connection loop, sender, barrier, drain, the SQLite store in
memory); only the MQTT client is a double: it records each publication as it is handed
over and lets the test decide when it is written (a broker that reads slowly, or a loop too
busy to write), so what goes ahead of what is decided by the adapter alone.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from functools import partial
from types import TracebackType

import aiomqtt
import pytest

from fcmaster.adapters.settings import SparkplugSettings
from fcmaster.adapters.sparkplug import adapter as adapter_module
from fcmaster.adapters.sparkplug.adapter import SparkplugAdapter
from fcmaster.adapters.sparkplug.payload import decode_payload
from tests.integration.gateway_double import FakeGateway
from tests.integration.waiting import wait_for

LIMIT_S = 20.0


@dataclass
class Handed:
    """One publication as the client took it."""

    topic: str
    historical: bool
    frequencies: list[float]  # its Output Frequency metrics, in order
    at: float = field(default_factory=time.monotonic)
    written: asyncio.Event = field(default_factory=asyncio.Event)
    written_at: float | None = None


class HeldClient:
    """An MQTT client whose publications are written only when the test lets them.

    ``reachable`` False: the broker is away (the CONNECT fails). ``hold`` True: each
    publication handed over waits until :meth:`write` lets it out.
    """

    def __init__(self) -> None:
        self.reachable = False
        self.hold = False
        self.handed: list[Handed] = []
        self.pending_calls_threshold = 0
        self._incoming: asyncio.Queue[aiomqtt.Message] = asyncio.Queue()

    def __call__(self, bd_seq: int) -> HeldClient:  # stands in for the adapter's _client_for
        return self

    async def __aenter__(self) -> HeldClient:
        if not self.reachable:
            raise aiomqtt.MqttError("[Errno 111] Connection refused")
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        return None

    async def subscribe(self, topic: str, qos: int = 0) -> list[int]:
        return [qos]

    async def unsubscribe(self, topic: str) -> None:
        return None  # the barrier: the broker has everything written before it

    async def publish(
        self,
        topic: str,
        payload: bytes,
        qos: int = 0,
        timeout: float | None = None,  # noqa: ASYNC109  # aiomqtt's signature
    ) -> None:
        frequencies: list[float] = []
        historical = False
        if "/DDATA/" in topic:
            for metric in decode_payload(payload).metrics:
                historical = historical or metric.is_historical
                if metric.name == "Output Frequency" and isinstance(metric.value, float):
                    frequencies.append(metric.value)
        handed = Handed(topic, historical, frequencies)
        self.handed.append(handed)
        if self.hold:
            async with asyncio.timeout(timeout):  # as aiomqtt's: TimeoutError past it
                await handed.written.wait()
        handed.written.set()
        handed.written_at = time.monotonic()

    def write(self) -> None:
        """Write everything handed over so far."""
        for handed in self.handed:
            handed.written.set()

    @property
    def messages(self) -> AsyncIterator[aiomqtt.Message]:
        return self._messages()

    async def _messages(self) -> AsyncIterator[aiomqtt.Message]:
        while True:
            yield await self._incoming.get()

    def history(self, device: str) -> list[float]:
        """The historical frequencies handed over for ``device``, in order."""
        return [
            hz
            for h in self.handed
            if h.historical and h.topic.endswith(f"/{device}")
            for hz in h.frequencies
        ]


@pytest.fixture
def client(monkeypatch: pytest.MonkeyPatch) -> HeldClient:
    held = HeldClient()
    monkeypatch.setattr(SparkplugAdapter, "_client_for", lambda self, bd_seq: held)
    return held


def settings() -> SparkplugSettings:
    return SparkplugSettings(
        url="mqtt://127.0.0.1:1",
        group_id="Plant",
        edge_node_id="gw-1",
        store=None,
        reconnect_min_s=0.01,
        reconnect_max_s=0.02,
    )


async def outage(
    gateway: FakeGateway, node: SparkplugAdapter, count: int
) -> dict[str, list[float]]:
    """Each drive online, then ``count`` changes, while the broker is away; their values."""
    made: dict[str, list[float]] = {"pump-1": [0.0], "fan-1": [0.0]}
    for drive in made:
        gateway.reply(drive, running=True, hz=0.0)
    for n in range(1, count + 1):
        for drive, values in made.items():
            hz = round(n / 10, 1)
            gateway.reply(drive, running=True, hz=hz)
            values.append(hz)
    await wait_for(lambda: node.forward.writer.written >= node.forward.last_n)
    return made


def rows(made: dict[str, list[float]]) -> int:
    """How many changes ``made`` holds."""
    return sum(len(values) for values in made.values())


def seen(client: HeldClient, hz: float) -> bool:
    """Whether the live change to ``hz`` has been handed over."""
    return any(h.frequencies == [hz] for h in client.handed)


def held_history(client: HeldClient) -> int:
    """History handed over and not yet written."""
    return sum(1 for h in client.handed if h.historical and not h.written.is_set())


async def test_live_data_goes_ahead_of_all_but_one_history_message_and_history_stays_whole(
    client: HeldClient,
) -> None:
    gateway = FakeGateway()
    async with asyncio.timeout(LIMIT_S), SparkplugAdapter(settings(), gateway) as node:
        made = await outage(gateway, node, 300)  # 12 history messages' worth
        client.hold = True  # the broker comes back, but takes what is written slowly
        client.reachable = True
        await wait_for(lambda: any(h.historical for h in client.handed))
        await asyncio.sleep(0.1)  # time enough for a drain that does not wait to go on
        # the first history message is not written: nothing else of history goes after it
        assert held_history(client) == 1
        gateway.reply("pump-1", running=True, hz=99.0)  # a live change meanwhile
        await wait_for(lambda: client.handed[-1].frequencies == [99.0])
        live = client.handed[-1]
        assert not live.historical
        assert sum(h.historical for h in client.handed) == 1  # behind just that one
        # Written one by one: each time, live data that came meanwhile goes first, and at
        # most one history message is ever waiting to be written.
        for hz in (98.0, 97.0, 96.0):
            ahead = len(client.handed)
            client.write()
            await wait_for(lambda: held_history(client) == 1 or node.forward.replayed >= rows(made))
            gateway.reply("pump-1", running=True, hz=hz)
            await wait_for(partial(seen, client, hz))
            at = next(i for i, h in enumerate(client.handed) if h.frequencies == [hz])
            assert sum(h.historical for h in client.handed[ahead:at]) <= 1
            assert held_history(client) <= 1
        client.hold = False
        client.write()
        await wait_for(lambda: node.forward.replayed >= rows(made))
    assert client.history("pump-1") == made["pump-1"]
    assert client.history("fan-1") == made["fan-1"]
    assert all(len(h.frequencies) <= adapter_module.HISTORY_MESSAGE_ROWS for h in client.handed)


async def test_history_waits_while_live_data_is_late_and_slows_down(client: HeldClient) -> None:
    gateway = FakeGateway()
    async with asyncio.timeout(LIMIT_S), SparkplugAdapter(settings(), gateway) as node:
        made = await outage(gateway, node, 300)
        client.hold = True
        client.reachable = True
        await wait_for(lambda: any(h.historical for h in client.handed))
        gateway.reply("pump-1", running=True, hz=99.0)  # live, behind one history message
        await wait_for(lambda: seen(client, 99.0))
        live = next(h for h in client.handed if h.frequencies == [99.0])
        # written late: live data waited twice as long as the drain lets it
        await asyncio.sleep(adapter_module.LIVE_LAG_S * 2)
        client.hold = False
        client.write()
        await wait_for(lambda: node.forward.replayed >= rows(made))
    assert live.written_at is not None
    lag = live.written_at - live.at
    after = [h for h in client.handed if h.historical and h.at > live.written_at]
    # the drain saw it and held history back as long, at a slower pace after
    assert after, "every history message went ahead of live data"
    assert after[0].at - live.written_at >= min(lag, 1.0) * 0.99
    assert node.history_held >= 1
