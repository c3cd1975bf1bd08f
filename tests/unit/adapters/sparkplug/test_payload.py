"""The Sparkplug B payload codec: golden bytes, round trips, and any bytes in."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given
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
from fcmaster.errors import ProtocolError
from tests.unit.adapters.sparkplug.strategies import payloads

# Worked by hand from the schema: field keys are (number << 3) | wire type.
GOLDEN = [
    pytest.param(
        Payload(
            timestamp=1, metrics=(Metric(name="a", datatype=DataType.BOOLEAN, value=True),), seq=0
        ),
        "08 01 12 07 0a 01 61 20 0b 70 01 18 00",
        id="boolean-metric-seq-0",
    ),
    pytest.param(
        Payload(metrics=(Metric(name="bdSeq", datatype=DataType.INT64, value=-1),)),
        "12 14 0a 05 62 64 53 65 71 20 04 58 ff ff ff ff ff ff ff ff ff 01",
        id="int64-two's-complement",
    ),
    pytest.param(
        Payload(
            metrics=(Metric(name="f", datatype=DataType.DOUBLE, value=50.0, is_historical=True),)
        ),
        "12 10 0a 01 66 20 0a 28 01 69 00 00 00 00 00 00 49 40",
        id="historical-double",
    ),
    pytest.param(
        Payload(metrics=(Metric(datatype=DataType.INT8, value=-2, alias=3, timestamp=300),)),
        "12 0d 10 03 18 ac 02 20 01 50 fe ff ff ff 0f",
        id="int8-in-32-bits-alias",
    ),
    pytest.param(
        Payload(
            metrics=(
                Metric(
                    name="u",
                    datatype=DataType.STRING,
                    properties=PropertySet((("engUnit", PropertyValue(DataType.STRING, "Hz")),)),
                ),
            )
        ),
        "12 1a 0a 01 75 20 0c 38 01 4a 11 0a 07 65 6e 67 55 6e 69 74 12 06 08 0c 42 02 48 7a",
        id="null-string-with-engunit",
    ),
]


@pytest.mark.parametrize(("payload", "wire"), GOLDEN)
def test_golden_bytes(payload: Payload, wire: str) -> None:
    assert encode_payload(payload).hex(" ") == wire
    expected = payload
    if any(m.value is None and not m.is_null for m in payload.metrics):
        expected = Payload(
            timestamp=payload.timestamp,
            metrics=tuple(
                Metric(name=m.name, datatype=m.datatype, properties=m.properties, is_null=True)
                for m in payload.metrics
            ),
        )
    assert decode_payload(bytes.fromhex(wire)) == expected


@given(payloads())
def test_decode_inverts_encode(payload: Payload) -> None:
    assert decode_payload(encode_payload(payload)) == payload


@given(payloads())
def test_encode_inverts_decode(payload: Payload) -> None:
    wire = encode_payload(payload)
    assert encode_payload(decode_payload(wire)) == wire


@given(st.binary(max_size=200))
def test_any_bytes_decode_or_raise_protocol_error_only(data: bytes) -> None:
    with contextlib.suppress(ProtocolError):
        decode_payload(data)


@given(payloads(), st.data())
def test_a_cut_or_flipped_payload_never_raises_anything_else(
    payload: Payload, data: st.DataObject
) -> None:
    wire = bytearray(encode_payload(payload))
    if wire:
        at = data.draw(st.integers(0, len(wire) - 1))
        wire[at] ^= data.draw(st.integers(1, 255))
        wire = wire[: data.draw(st.integers(0, len(wire)))]
    with contextlib.suppress(ProtocolError):
        decode_payload(bytes(wire))


@pytest.mark.parametrize(
    ("datatype", "value"),
    [
        (DataType.INT8, 128),
        (DataType.UINT16, -1),
        (DataType.INT64, 1 << 63),
        (DataType.BOOLEAN, 1),
        (DataType.DOUBLE, "1.0"),
        (DataType.INT32, True),
        (DataType.DATASET, b""),
    ],
)
def test_a_value_its_datatype_cannot_carry_is_refused(datatype: DataType, value: object) -> None:
    metric = Metric(name="m", datatype=datatype, value=value)  # type: ignore[arg-type]  # wrong on purpose
    with pytest.raises(ValueError, match=datatype.name):
        encode_payload(Payload(metrics=(metric,)))


def test_a_value_of_another_kind_than_its_datatype_is_malformed() -> None:
    # datatype Boolean (11) with a double_value (field 13)
    wire = bytes.fromhex("12 0b 20 0b 69 00 00 00 00 00 00 49 40")
    with pytest.raises(ProtocolError, match="BOOLEAN metric carries a value of another kind"):
        decode_payload(wire)


def test_unknown_fields_are_skipped() -> None:
    known = encode_payload(Payload(timestamp=5, seq=1))
    extra = bytes.fromhex("a8 06 07 b1 06 01 02 03 04 05 06 07 08 ba 06 02 68 69 c5 06 01 02 03 04")
    assert decode_payload(known + extra) == Payload(timestamp=5, seq=1)
