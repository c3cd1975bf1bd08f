"""The Sparkplug edge node against a real mosquitto and a host application from the spec."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import pytest

from fcmaster.adapters.settings import SparkplugSettings
from fcmaster.adapters.sparkplug.adapter import SparkplugAdapter
from fcmaster.adapters.sparkplug.payload import DataType, Metric
from tests.integration.gateway_double import FakeGateway
from tests.integration.mosquitto import Broker
from tests.integration.sparkplug_host import Received, SparkplugHost
from tests.integration.tahu import tahu_decode, tahu_marks, tahu_shape
from tests.integration.waiting import wait_for

LIMIT_S = 30.0
GROUP, NODE = "Plant", "gw-1"

# The metrics DESIGN.md names for every drive, with their datatypes.
DEVICE_METRICS = {
    "Output Frequency": DataType.DOUBLE,
    "Reference": DataType.DOUBLE,
    "Status/Running": DataType.BOOLEAN,
    "Status/Fault": DataType.BOOLEAN,
    "Status/Warning": DataType.BOOLEAN,
    "Status/At Reference": DataType.BOOLEAN,
    "Status/Word": DataType.INT64,
    "Status/Direction": DataType.STRING,
    "Alarms": DataType.STRING,
    "Warnings": DataType.STRING,
    "Watchdog/Verdict": DataType.STRING,
    "Control/Run": DataType.BOOLEAN,
    "Control/Reference Hz": DataType.DOUBLE,
    "Control/Reset": DataType.BOOLEAN,
    "Control/Last Outcome": DataType.STRING,
    "Control/Last Reason": DataType.STRING,
}


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with Broker(tmp_path) as running:
        yield running


def settings(broker: Broker, tmp_path: Path, **changes: object) -> SparkplugSettings:
    fields: dict[str, object] = {
        "url": broker.url,
        "group_id": GROUP,
        "edge_node_id": NODE,
        "primary_host_id": "scada",
        "store": str(tmp_path / "spool" / "sparkplug.db"),
        "reconnect_min_s": 0.05,
        "reconnect_max_s": 0.2,
        "rebirth_min_s": 0.0,
        **changes,
    }
    return SparkplugSettings(**fields)  # type: ignore[arg-type]  # a test's few settings


def unit(received: Received, name: str) -> object:
    properties = received.metric(name).properties
    found = None if properties is None else properties.get("engUnit")
    return None if found is None else found.value


def is_pump(received: Received) -> bool:
    return received.device == "pump-1"


async def test_births_wait_for_the_primary_host_and_pair_with_deaths_by_bdseq(
    broker: Broker, tmp_path: Path
) -> None:
    gateway = FakeGateway()
    gateway.reply("pump-1", running=True, hz=25.0, value=("16-14", 3.5, "A"))
    gateway.reply("fan-1")
    async with (
        asyncio.timeout(LIMIT_S),
        SparkplugHost(broker, GROUP, announce=False) as host,
    ):
        async with SparkplugAdapter(settings(broker, tmp_path), gateway) as node:
            await node.connected.wait()
            await asyncio.sleep(0.3)  # connected and subscribed, but the host has said nothing
            assert host.received == []

            await host.online()
            birth = await host.wait("NBIRTH")
            assert birth.payload.seq == 0
            assert birth.values() == {"bdSeq": 0, "Node Control/Rebirth": False}
            assert birth.metric("bdSeq").datatype == DataType.INT64
            pump = await host.wait("DBIRTH", is_pump)
            types = {m.name: m.datatype for m in pump.payload.metrics}
            assert {n: types.get(n) for n in DEVICE_METRICS} == DEVICE_METRICS
            assert types["Values/Motor Current"] == DataType.DOUBLE
            assert (
                pump.metric("Values/Motor Current").value,
                unit(pump, "Values/Motor Current"),
            ) == (
                3.5,
                "A",
            )
            assert (pump.metric("Output Frequency").value, unit(pump, "Output Frequency")) == (
                25.0,
                "Hz",
            )
            assert unit(pump, "Control/Reference Hz") == "Hz"
            assert pump.metric("Reference").value == 50.0
            await host.wait("DBIRTH", lambda r: r.device == "fan-1")

            mark = len(host.received)
            gateway.reply("pump-1", running=True, hz=40.0, value=("16-14", 3.5, "A"))
            data = await host.wait("DDATA", is_pump, start=mark)
            assert data.values()["Output Frequency"] == 40.0
            assert "Status/Running" not in data.values()  # by exception: only what changed

            await host.offline()
            death = await host.wait("NDEATH")
            assert host.deaths == [(0, True)]
            assert death.payload.seq is None
            await asyncio.sleep(0.3)
            assert host.on("NBIRTH") == [birth]  # waits for the host again

            await host.online()
            again = await host.wait("NBIRTH", start=death.index)
            assert again.values()["bdSeq"] == 1  # a new connection, the next bdSeq
            await host.wait("DBIRTH", is_pump, start=again.index)
            mark = len(host.received)
        # leaving on purpose: its own NDEATH, with the bdSeq of its birth
        await host.wait("NDEATH", start=mark)
    assert host.deaths == [(0, True), (1, True)]
    assert host.problems == []
    # An independent decoder reads every message as we do: births, data, deaths.
    if not tahu_marks():
        kinds = {r.kind for r in host.received}
        assert kinds >= {"NBIRTH", "DBIRTH", "DDATA", "NDEATH"}
        decoded = tahu_decode([r.raw for r in host.received])
        assert decoded == [tahu_shape(r.payload) for r in host.received]


def frequency_is(hz: float) -> Callable[[Received], bool]:
    def check(received: Received) -> bool:
        return is_pump(received) and received.values().get("Output Frequency") == hz

    return check


async def test_seq_runs_across_the_session_through_rebirths_and_a_drive_going_away(
    broker: Broker, tmp_path: Path
) -> None:
    gateway = FakeGateway()
    gateway.reply("pump-1", running=True, hz=1.0)
    gateway.reply("fan-1")
    options = settings(broker, tmp_path, rebirth_min_s=3600.0)
    async with (
        asyncio.timeout(LIMIT_S),
        SparkplugHost(broker, GROUP) as host,
        SparkplugAdapter(options, gateway) as node,
    ):
        await host.wait("DBIRTH", lambda r: r.device == "fan-1")
        for step in range(2, 302):  # past 255: seq wraps to 0 and goes on (the host checks)
            gateway.reply("pump-1", running=True, hz=step / 10)
            await asyncio.sleep(0)
        last = await host.wait("DDATA", frequency_is(30.1))
        seqs = [r.payload.seq for r in host.received]
        assert seqs.index(255) < seqs.index(0, 1) < len(seqs) - 1

        await host.rebirth(NODE)
        rebirth = await host.wait("NBIRTH", start=last.index)
        assert rebirth.values()["bdSeq"] == 0  # the same session: the same Will, the same bdSeq
        await host.wait("DBIRTH", lambda r: r.device == "fan-1", start=rebirth.index)
        await host.rebirth(NODE)  # too soon after the last: ignored
        gateway.reply("pump-1", running=True, hz=7.0)
        marker = await host.wait("DDATA", frequency_is(7.0), start=rebirth.index)
        await host.rebirth(NODE)
        gateway.reply("pump-1", running=True, hz=8.0)
        await host.wait("DDATA", frequency_is(8.0), start=marker.index)
        assert len(host.on("NBIRTH")) == 2
        assert node.node.rebirths_ignored == 2

        gateway.offline("fan-1")
        death = await host.wait("DDEATH", lambda r: r.device == "fan-1")
        assert death.payload.metrics == ()
        gateway.reply("fan-1")
        await host.wait("DBIRTH", lambda r: r.device == "fan-1", start=death.index)
        gateway.reply("pump-1", running=True, hz=9.0)
        await host.wait("DDATA", frequency_is(9.0), start=death.index)
    assert host.problems == []


def outcome_of(received: Received) -> tuple[object, object]:
    values = received.values()
    return values.get("Control/Last Outcome"), values.get("Control/Last Reason")


def has_outcome(received: Received) -> bool:
    return is_pump(received) and "Control/Last Outcome" in received.values()


def write(name: str, value: float | bool) -> Metric:
    datatype = DataType.BOOLEAN if isinstance(value, bool) else DataType.DOUBLE
    return Metric(name=name, datatype=datatype, value=value)


async def test_dcmd_goes_the_command_path_and_each_write_publishes_its_outcome(
    broker: Broker, tmp_path: Path
) -> None:
    gateway = FakeGateway()
    gateway.reply("pump-1", running=False, hz=0.0)
    async with (
        asyncio.timeout(LIMIT_S),
        SparkplugHost(broker, GROUP) as host,
        SparkplugAdapter(settings(broker, tmp_path, commands=True), gateway),
    ):
        birth = await host.wait("DBIRTH", is_pump)
        assert outcome_of(birth) == ("", "")

        await host.dcmd(NODE, "pump-1", write("Control/Reference Hz", 30.0))
        done = await host.wait("DDATA", has_outcome)
        assert outcome_of(done) == ("done", "")
        ((drive, command),) = gateway.executed
        assert (drive, command.action.value, command.reference_pct) == (
            "pump-1",
            "set_reference",
            60.0,
        )
        assert command.actor == f"sparkplug:{NODE}"

        await host.dcmd(NODE, "pump-1", write("Control/Reference Hz", 50.5))  # max 50 Hz
        beyond = await host.wait("DDATA", has_outcome, start=done.index + 1)
        assert outcome_of(beyond)[0] == "not_allowed"
        assert "50" in str(outcome_of(beyond)[1])
        await host.dcmd(NODE, "pump-1", write("Control/Reference Hz", -5.0))
        negative = await host.wait("DDATA", has_outcome, start=beyond.index + 1)
        assert outcome_of(negative)[0] == "invalid"
        await host.dcmd(NODE, "pump-1", write("Output Frequency", 10.0))
        not_writable = await host.wait("DDATA", has_outcome, start=negative.index + 1)
        assert outcome_of(not_writable)[0] == "invalid"
        assert "not writable" in str(outcome_of(not_writable)[1])
        assert len(gateway.executed) == 1  # no refusal reached a line

        await host.dcmd(NODE, "pump-1", write("Control/Run", True), write("Control/Reset", True))
        started = await host.wait("DDATA", has_outcome, start=not_writable.index + 1)
        await host.wait("DDATA", has_outcome, start=started.index + 1)
        assert [c.action.value for _, c in gateway.executed[1:]] == ["start", "reset"]
    assert host.problems == []


async def test_with_commands_off_a_dcmd_is_not_allowed_and_reaches_no_line(
    broker: Broker, tmp_path: Path
) -> None:
    gateway = FakeGateway()
    gateway.reply("pump-1")
    async with (
        asyncio.timeout(LIMIT_S),
        SparkplugHost(broker, GROUP) as host,
        SparkplugAdapter(settings(broker, tmp_path), gateway),
    ):
        await host.wait("DBIRTH", is_pump)
        await host.dcmd(NODE, "pump-1", write("Control/Run", True))
        refused = await host.wait("DDATA", has_outcome)
        assert outcome_of(refused) == (
            "not_allowed",
            "commands over Sparkplug are off (sparkplug.commands: false)",
        )
    assert gateway.executed == []
    assert host.problems == []


async def changes(node: SparkplugAdapter, gateway: FakeGateway, steps: list[float]) -> None:
    """One reply per step, each taken in by the edge node before the next (none conflated)."""
    for hz in steps:
        expected = node.forward.last_n + 1
        gateway.reply("pump-1", running=True, hz=hz)
        await wait_for(lambda: node.forward.last_n >= expected)  # noqa: B023 - awaited here


async def gateway_changes_confirmed(node: SparkplugAdapter) -> None:
    """Until every change is confirmed to the store and no barrier is in flight."""
    await wait_for(
        lambda: (
            node.forward.confirmed >= node.forward.last_n
            and node.barriers == node.barriers_answered
        )
    )


def history(host: SparkplugHost) -> list[tuple[object, int | None]]:
    """The pump's historical Output Frequency values and their times, in arrival order."""
    return [
        (m.value, m.timestamp)
        for r in host.on("DDATA", "pump-1")
        for m in r.payload.metrics
        if m.is_historical and m.name == "Output Frequency"
    ]


async def test_changes_in_a_broker_outage_and_at_its_failing_moment_arrive_as_history_in_order(
    broker: Broker, tmp_path: Path
) -> None:
    gateway = FakeGateway()
    gateway.reply("pump-1", running=True, hz=1.0)
    stuck = [round(1.0 + i / 10, 1) for i in range(1, 11)]  # 1.1 … 2.0: into a frozen broker
    away = [round(2.0 + i / 10, 1) for i in range(1, 11)]  # 2.1 … 3.0: while it is gone
    async with (
        asyncio.timeout(LIMIT_S),
        SparkplugAdapter(settings(broker, tmp_path), gateway) as node,
    ):
        async with SparkplugHost(broker, GROUP) as host:
            await host.wait("DBIRTH", is_pump)
        # live data and no barrier in flight: the next one is asked for after what follows
        await gateway_changes_confirmed(node)
        # The broker freezes: the connection stays open and what the node writes to its
        # socket is lost with the broker, before anyone can notice.
        barriers = node.barriers
        broker.pause()
        await changes(node, gateway, stuck)
        await wait_for(lambda: node.published_through >= node.forward.last_n)  # in the socket
        # and a barrier asked after at least one of them (a node that took the socket's word
        # for it would count them delivered now)
        await wait_for(lambda: node.barriers > barriers)
        await broker.stop()
        await changes(node, gateway, away)
        await broker.start()
        async with SparkplugHost(broker, GROUP) as host:
            birth = await host.wait("NBIRTH")
            # one more for each CONNECT, refused ones while the broker was away too
            assert birth.values()["bdSeq"] == node.node.bd_seq > 0
            live = await host.wait("DBIRTH", is_pump)
            assert live.values()["Output Frequency"] == 3.0
            while len(history(host)) < len(stuck + away):
                await host.wait("DDATA", is_pump, start=len(host.received))
            assert [value for value, _ in history(host)] == stuck + away
            times = [at or 0 for _, at in history(host)]
            assert times == sorted(times)
            assert all(r.index > live.index for r in host.on("DDATA", "pump-1"))
            gateway.reply("pump-1", running=True, hz=4.0)  # live again, not historical
            now = await host.wait("DDATA", frequency_is(4.0))
            assert not now.metric("Output Frequency").is_historical
        assert host.problems == []
        assert node.forward.replayed == len(stuck + away)
