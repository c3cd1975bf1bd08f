"""The edge node's session rules, without a broker: seq, bdSeq, STATE, Rebirth, devices."""

from __future__ import annotations

import json

from hypothesis import given
from hypothesis import strategies as st

from fcmaster.adapters.sparkplug.metrics import Reading
from fcmaster.adapters.sparkplug.node import (
    Disconnect,
    EdgeNode,
    Effect,
    Phase,
    Publish,
    parse_state,
)
from fcmaster.adapters.sparkplug.payload import DataType, Metric, decode_payload

DEVICES = {"pump-1": {"Output Frequency": Reading(DataType.DOUBLE, 10.0, "Hz", 1)}}
FREQ = {"Output Frequency": Reading(DataType.DOUBLE, 11.0, "Hz", 2)}


def node(**options: object) -> EdgeNode:
    fields: dict[str, object] = {"group_id": "G", "edge_node_id": "E", **options}
    return EdgeNode(**fields)  # type: ignore[arg-type]  # a test's few options


def state(online: bool, timestamp: int) -> bytes:
    return json.dumps({"online": online, "timestamp": timestamp}).encode()


def published(effects: list[Effect]) -> list[tuple[str, int | None]]:
    return [
        (e.topic.split("/", 2)[2], decode_payload(e.payload).seq)
        for e in effects
        if isinstance(e, Publish)
    ]


def test_without_a_primary_host_the_births_follow_the_connection() -> None:
    edge = node()
    effects = edge.connected(7, 0.0, 1000, DEVICES)
    assert published(effects) == [("NBIRTH/E", 0), ("DBIRTH/E/pump-1", 1)]
    birth = decode_payload(effects[0].payload)  # type: ignore[union-attr]
    assert [(m.name, m.datatype, m.value) for m in birth.metrics] == [
        ("bdSeq", DataType.INT64, 7),
        ("Node Control/Rebirth", DataType.BOOLEAN, False),
    ]
    will = edge.will(7, 1000)
    assert (will.topic, will.qos) == ("spBv1.0/G/NDEATH/E", 1)
    assert decode_payload(will.payload).seq is None
    assert decode_payload(will.payload).metrics[0].value == 7


def test_state_online_births_offline_deaths_and_stale_states_are_ignored() -> None:
    edge = node(primary_host_id="H")
    assert edge.subscriptions() == ["spBv1.0/G/NCMD/E", "spBv1.0/G/DCMD/E/+", "spBv1.0/STATE/H"]
    assert edge.connected(1, 0.0, 0, DEVICES) == []
    assert edge.host_state(state(False, 10), 0.0, 0, DEVICES) == []  # waiting: stays so
    assert published(edge.host_state(state(True, 20), 0.0, 0, DEVICES) or [])[0] == ("NBIRTH/E", 0)
    assert edge.host_state(state(False, 15), 0.0, 0, DEVICES) == []  # older than the last
    effects = edge.host_state(state(False, 30), 0.0, 0, DEVICES)
    assert effects is not None
    assert [type(e) for e in effects] == [Publish, Disconnect]
    assert effects[0].topic == "spBv1.0/G/NDEATH/E"  # type: ignore[union-attr]
    assert edge.phase is Phase.WAITING
    assert edge.host_state(b"online", 0.0, 0, DEVICES) is None


def test_a_state_payload_must_be_sparkplug_3s_json() -> None:
    assert parse_state(state(True, 5)) == (True, 5)
    for bad in (b"ONLINE", b"[]", b'{"online": 1, "timestamp": 5}', b'{"online": true}'):
        assert parse_state(bad) is None


@given(st.lists(st.sampled_from(["data", "rebirth", "offline", "online"]), max_size=400))
def test_seq_goes_up_by_one_mod_256_over_everything_but_ndeath(steps: list[str]) -> None:
    edge = node(rebirth_min_s=0.0)
    seqs = [s or 0 for _, s in published(edge.connected(0, 0.0, 0, DEVICES))]
    rebirth = (Metric(name="Node Control/Rebirth", datatype=DataType.BOOLEAN, value=True),)
    for step in steps:
        if step == "data":
            effects = edge.device_data("pump-1", FREQ, DEVICES["pump-1"], 0)
        elif step == "rebirth":
            effects = edge.node_command(rebirth, 0.0, 0, DEVICES)
        elif step == "offline":
            effects = edge.device_offline("pump-1", 0)
        else:
            effects = edge.device_online("pump-1", DEVICES["pump-1"], 0)
        for topic, seq in published(effects):
            expected = 0 if topic.startswith("NBIRTH") else (seqs[-1] + 1) % 256
            assert seq == expected
            seqs.append(expected)


def test_a_rebirth_sooner_than_the_limit_after_the_last_one_is_ignored() -> None:
    edge = node(rebirth_min_s=5.0)
    edge.connected(0, 0.0, 0, DEVICES)
    rebirth = (Metric(name="Node Control/Rebirth", datatype=DataType.BOOLEAN, value=True),)
    assert published(edge.node_command(rebirth, 0.1, 0, DEVICES))[0] == ("NBIRTH/E", 0)
    assert edge.node_command(rebirth, 4.0, 0, DEVICES) == []
    assert edge.node_command(rebirth, 5.2, 0, DEVICES) != []
    false = (Metric(name="Node Control/Rebirth", datatype=DataType.BOOLEAN, value=False),)
    assert edge.node_command(false, 100.0, 0, DEVICES) == []
    assert edge.rebirths_ignored == 1


def test_a_metric_the_device_was_not_born_with_makes_a_new_dbirth() -> None:
    edge = node()
    edge.connected(0, 0.0, 0, DEVICES)
    current = Reading(DataType.DOUBLE, 3.5, "A", 3)
    readings = {**DEVICES["pump-1"], "Values/Motor Current": current}
    effects = edge.device_data("pump-1", {"Values/Motor Current": current}, readings, 0)
    assert published(effects) == [("DBIRTH/E/pump-1", 2)]
    history = [("Values/Motor Current", current), ("Gone", Reading(DataType.DOUBLE, 1.0))]
    (ddata,) = edge.device_history("pump-1", history, 0)
    metrics = decode_payload(ddata.payload).metrics  # type: ignore[union-attr]
    assert [(m.name, m.is_historical, m.timestamp) for m in metrics] == [
        ("Values/Motor Current", True, 3)
    ]


def test_commands_are_told_by_their_topics() -> None:
    edge = node()
    assert edge.command_device("spBv1.0/G/NCMD/E") == ""
    assert edge.command_device("spBv1.0/G/DCMD/E/pump-1") == "pump-1"
    assert edge.command_device("spBv1.0/G/DCMD/E/a/b") is None
    assert edge.command_device("spBv1.0/G/DCMD/F/pump-1") is None
