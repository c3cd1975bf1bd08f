"""What fcmaster encodes, Eclipse Tahu's JavaScript codec decodes to the same payload."""

from __future__ import annotations

from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from fcmaster.adapters.sparkplug.payload import (
    DataType,
    Metric,
    Payload,
    PropertySet,
    PropertyValue,
    decode_payload,
    encode_payload,
)
from tests.integration.tahu import tahu_decode, tahu_marks, tahu_shape
from tests.unit.adapters.sparkplug.strategies import payloads

pytestmark = tahu_marks()


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
