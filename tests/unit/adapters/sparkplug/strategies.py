"""Hypothesis strategies for Sparkplug B payloads (shared by the codec's tests)."""

from __future__ import annotations

from hypothesis import strategies as st

from fcmaster.adapters.sparkplug.payload import (
    DataType,
    Metric,
    Payload,
    PropertySet,
    PropertyValue,
    Value,
)

U64 = (1 << 64) - 1
_INTS = {
    DataType.INT8: (-(1 << 7), (1 << 7) - 1),
    DataType.INT16: (-(1 << 15), (1 << 15) - 1),
    DataType.INT32: (-(1 << 31), (1 << 31) - 1),
    DataType.INT64: (-(1 << 63), (1 << 63) - 1),
    DataType.UINT8: (0, (1 << 8) - 1),
    DataType.UINT16: (0, (1 << 16) - 1),
    DataType.UINT32: (0, (1 << 32) - 1),
    DataType.UINT64: (0, U64),
    DataType.DATETIME: (0, U64),
}


def values(datatype: DataType, *, uint32_max: int = (1 << 32) - 1) -> st.SearchStrategy[Value]:
    """Values ``datatype`` carries (floats finite, Float ones exactly representable)."""
    if datatype in _INTS:
        low, high = _INTS[datatype]
        return st.integers(low, uint32_max if datatype == DataType.UINT32 else high)
    if datatype == DataType.FLOAT:
        return st.floats(width=32, allow_nan=False, allow_infinity=False)
    if datatype == DataType.DOUBLE:
        return st.floats(allow_nan=False, allow_infinity=False)
    if datatype == DataType.BOOLEAN:
        return st.booleans()
    if datatype in (DataType.STRING, DataType.TEXT, DataType.UUID):
        return st.text(max_size=20)
    return st.binary(max_size=20)


SCALARS = [t for t in DataType if t.value <= 18 and t != DataType.DATASET]
PROPERTY_TYPES = [t for t in SCALARS if t not in (DataType.BYTES, DataType.FILE)]


@st.composite
def property_values(draw: st.DrawFn, depth: int = 0) -> PropertyValue:
    """One property value, now and then a nested set or a null."""
    if depth < 2 and draw(st.integers(0, 9)) == 0:
        return PropertyValue(DataType.PROPERTY_SET, draw(property_sets(depth + 1)))
    datatype = draw(st.sampled_from(PROPERTY_TYPES))
    value = draw(st.none() | values(datatype, uint32_max=(1 << 31) - 1))
    return PropertyValue(datatype, value)


@st.composite
def property_sets(draw: st.DrawFn, depth: int = 0) -> PropertySet:
    """A property set with distinct keys."""
    keys = draw(st.lists(st.text(min_size=1, max_size=8), max_size=3, unique=True))
    return PropertySet(tuple((key, draw(property_values(depth))) for key in keys))


@st.composite
def metrics(draw: st.DrawFn, *, uint32_max: int = (1 << 32) - 1) -> Metric:
    """One metric of a scalar datatype, sometimes null, historical or with properties."""
    datatype = draw(st.sampled_from(SCALARS))
    value = draw(st.none() | values(datatype, uint32_max=uint32_max))
    return Metric(
        name=draw(st.none() | st.text(max_size=30)),
        alias=draw(st.none() | st.integers(0, U64)),
        timestamp=draw(st.none() | st.integers(0, U64)),
        datatype=datatype,
        is_historical=draw(st.booleans()),
        is_transient=draw(st.booleans()),
        is_null=value is None,
        properties=draw(st.none() | property_sets()),
        value=value,
    )


@st.composite
def payloads(draw: st.DrawFn, *, uint32_max: int = (1 << 32) - 1) -> Payload:
    """A payload of up to five metrics."""
    return Payload(
        timestamp=draw(st.none() | st.integers(0, U64)),
        metrics=tuple(draw(st.lists(metrics(uint32_max=uint32_max), max_size=5))),
        seq=draw(st.none() | st.integers(0, 255)),
        uuid=draw(st.none() | st.text(max_size=10)),
        body=draw(st.none() | st.binary(max_size=10)),
    )
