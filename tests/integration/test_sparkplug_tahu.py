"""What fcmaster encodes, Eclipse Tahu's JavaScript codec decodes to the same payload."""

from __future__ import annotations

from typing import Any

from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from fcmaster.adapters.sparkplug.payload import (
    DataType,
    Metric,
    Payload,
    PropertySet,
    PropertyValue,
    Value,
    decode_payload,
    encode_payload,
)
from tests.integration.tahu import tahu_decode, tahu_marks
from tests.unit.adapters.sparkplug.strategies import payloads

pytestmark = tahu_marks()

_NAMES = {
    DataType.UINT8: "UInt8", DataType.UINT16: "UInt16", DataType.UINT32: "UInt32",
    DataType.UINT64: "UInt64", DataType.DATETIME: "DateTime", DataType.UUID: "UUID",
    DataType.PROPERTY_SET: "PropertySet",
}  # fmt: skip
_LONGS = (DataType.INT64, DataType.UINT32, DataType.UINT64, DataType.DATETIME)


def _type(datatype: DataType) -> str:
    return _NAMES.get(datatype) or datatype.name.title()


def _value(datatype: DataType, value: Value | PropertySet | None) -> Any:
    if value is None:
        return None
    if isinstance(value, PropertySet):
        return _properties(value)
    if isinstance(value, bytes):
        return value.hex()
    if datatype in _LONGS:
        # Tahu reads a UInt32 with Long.toInt(): fine below 2**31, which the strategy keeps to
        return value if datatype == DataType.UINT32 else str(value)
    return value


def _properties(properties: PropertySet) -> dict[str, Any]:
    return {key: _property(prop) for key, prop in properties.items}


def _property(prop: PropertyValue) -> dict[str, Any]:
    return {"type": _type(prop.type), "value": _value(prop.type, prop.value)}


def _metric(metric: Metric) -> dict[str, Any]:
    out: dict[str, Any] = {
        "type": _type(metric.datatype),
        "value": _value(metric.datatype, metric.value),
    }
    if metric.name is not None:
        out["name"] = metric.name
    if metric.timestamp is not None:
        out["timestamp"] = str(metric.timestamp)
    if metric.alias is not None:
        out["alias"] = str(metric.alias)
    if metric.is_historical:
        out["isHistorical"] = True
    if metric.is_transient:
        out["isTransient"] = True
    if metric.properties is not None:
        out["properties"] = _properties(metric.properties)
    return out


def tahu_shape(payload: Payload) -> dict[str, Any]:
    """``payload`` as Tahu's ``decodePayload`` presents it (see tests/node/sparkplug/decode.js)."""
    out: dict[str, Any] = {}
    if payload.timestamp is not None:
        out["timestamp"] = str(payload.timestamp)
    out["metrics"] = [_metric(m) for m in payload.metrics]  # protobufjs: always a list
    if payload.seq is not None:
        out["seq"] = str(payload.seq)
    if payload.uuid is not None:
        out["uuid"] = payload.uuid
    if payload.body is not None:
        out["body"] = payload.body.hex()
    return out


# Each example is a node process: few examples, each a batch, and no shrinking (the failing
# batch is printed whole; tahu_shape's difference names the payload).
@settings(
    max_examples=4,
    deadline=None,
    phases=(Phase.explicit, Phase.reuse, Phase.generate),
    suppress_health_check=[HealthCheck.data_too_large, HealthCheck.too_slow],
)
@given(st.lists(payloads(uint32_max=(1 << 31) - 1), min_size=40, max_size=40))
def test_tahu_decodes_what_we_encode(batch: list[Payload]) -> None:
    wires = [encode_payload(p) for p in batch]
    # Our own reading of the wire: a Float comes back as the float32 it became.
    expected = [tahu_shape(decode_payload(w)) for w in wires]
    assert tahu_decode(wires) == expected


def test_a_birth_as_tahu_reads_it() -> None:
    units = PropertySet((("engUnit", PropertyValue(DataType.STRING, "Hz")),))
    birth = Payload(
        timestamp=1_764_230_400_000,
        seq=0,
        metrics=(
            Metric(name="bdSeq", datatype=DataType.INT64, value=7, timestamp=1_764_230_400_000),
            Metric(name="Node Control/Rebirth", datatype=DataType.BOOLEAN, value=False),
            Metric(name="Output Frequency", datatype=DataType.DOUBLE, value=49.5, properties=units),
            Metric(name="Status/Word", datatype=DataType.INT32, value=-1),
            Metric(name="Reference", datatype=DataType.DOUBLE, is_null=True),
        ),
    )
    (decoded,) = tahu_decode([encode_payload(birth)])
    assert decoded == {
        "timestamp": "1764230400000",
        "seq": "0",
        "metrics": [
            {"name": "bdSeq", "type": "Int64", "value": "7", "timestamp": "1764230400000"},
            {"name": "Node Control/Rebirth", "type": "Boolean", "value": False},
            {
                "name": "Output Frequency", "type": "Double", "value": 49.5,
                "properties": {"engUnit": {"type": "String", "value": "Hz"}},
            },
            {"name": "Status/Word", "type": "Int32", "value": -1},
            {"name": "Reference", "type": "Double", "value": None},
        ],
    }  # fmt: skip
