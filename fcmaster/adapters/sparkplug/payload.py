"""The Sparkplug B payload: protobuf wire encoding and decoding, sans-I/O.

The schema is Eclipse Tahu's ``sparkplug_b.proto`` (Sparkplug 3.0, proto2), of which this
module speaks the parts an edge node for drives needs: ``Payload`` (timestamp, metrics, seq,
uuid, body), ``Metric`` (name, alias, timestamp, datatype, is_historical, is_transient,
is_null, properties and a scalar value) and ``PropertySet`` (engineering units and the
like). ``metadata``, DataSet and Template values are skipped when decoding, never produced.

The protobuf wire format in brief: each field is a key varint ``(number << 3) | wire_type``
followed by a varint (type 0), 8 bytes little-endian (1), a length varint and that many bytes
(2: strings, bytes, nested messages) or 4 bytes little-endian (5). Unknown fields are skipped
by their wire type, so a newer peer's additions never break decoding.

Where a value goes (Sparkplug 3.0, "Datatypes"; Tahu's codecs agree): Int8/16/32 and
UInt8/16 in ``int_value`` (uint32, signed ones as 32-bit two's complement); Int64, UInt32,
UInt64 and DateTime in ``long_value`` (uint64, Int64 as 64-bit two's complement); Float,
Double, Boolean; String, Text and UUID in ``string_value``; Bytes and File in
``bytes_value``.

:func:`decode_payload` raises only :class:`~fcmaster.errors.ProtocolError`, whatever the bytes.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from fcmaster.errors import ProtocolError

__all__ = [
    "DataType",
    "Metric",
    "Payload",
    "PropertySet",
    "PropertyValue",
    "Value",
    "decode_payload",
    "encode_payload",
]

Value = int | float | bool | str | bytes


class DataType(IntEnum):
    """Sparkplug B datatypes (the ``DataType`` enum of the schema)."""

    INT8 = 1
    INT16 = 2
    INT32 = 3
    INT64 = 4
    UINT8 = 5
    UINT16 = 6
    UINT32 = 7
    UINT64 = 8
    FLOAT = 9
    DOUBLE = 10
    BOOLEAN = 11
    STRING = 12
    DATETIME = 13
    TEXT = 14
    UUID = 15
    DATASET = 16
    BYTES = 17
    FILE = 18
    TEMPLATE = 19
    PROPERTY_SET = 20
    PROPERTY_SET_LIST = 21


@dataclass(slots=True, frozen=True)
class PropertyValue:
    """One property: its datatype and value (None: ``is_null``)."""

    type: DataType
    value: Value | PropertySet | None = None


@dataclass(slots=True, frozen=True)
class PropertySet:
    """Named properties of a metric, in order (``engUnit`` carries engineering units)."""

    items: tuple[tuple[str, PropertyValue], ...] = ()

    def get(self, key: str) -> PropertyValue | None:
        """The property ``key``, or None."""
        return next((value for name, value in self.items if name == key), None)


@dataclass(slots=True, frozen=True, kw_only=True)
class Metric:
    """One metric; ``value`` None with ``is_null`` for a metric whose value is not known."""

    name: str | None = None
    alias: int | None = None
    timestamp: int | None = None  # milliseconds since the epoch, UTC
    datatype: DataType
    is_historical: bool = False
    is_transient: bool = False
    is_null: bool = False
    properties: PropertySet | None = None
    value: Value | None = None


@dataclass(slots=True, frozen=True, kw_only=True)
class Payload:
    """A Sparkplug B payload; ``seq`` is None only in NDEATH."""

    timestamp: int | None = None
    metrics: tuple[Metric, ...] = ()
    seq: int | None = None
    uuid: str | None = None
    body: bytes | None = None


# Field numbers of the schema.
_P_TIMESTAMP, _P_METRICS, _P_SEQ, _P_UUID, _P_BODY = 1, 2, 3, 4, 5
_M_NAME, _M_ALIAS, _M_TIMESTAMP, _M_DATATYPE = 1, 2, 3, 4
_M_HISTORICAL, _M_TRANSIENT, _M_NULL, _M_PROPERTIES = 5, 6, 7, 9
_M_VALUES = 10  # int, long, float, double, boolean, string, bytes: 10 to 16
_S_KEYS, _S_VALUES = 1, 2
_V_TYPE, _V_NULL = 1, 2
_V_VALUES = 3  # int, long, float, double, boolean, string: 3 to 8; propertyset 9
_V_PROPERTY_SET = 9

_VARINT, _FIXED64, _LENGTH, _FIXED32 = 0, 1, 2, 5
_U64 = (1 << 64) - 1
_U32 = (1 << 32) - 1
MAX_DEPTH = 8  # property sets nested deeper than this are refused

# Each datatype's slot among the value fields (0 int, 1 long, 2 float, 3 double, 4 boolean,
# 5 string, 6 bytes) and, for integers, its bit width and whether it is signed.
_INT, _LONG, _FLOAT, _DOUBLE, _BOOL, _STRING, _BYTES = range(7)
_SLOT = {
    DataType.INT8: _INT, DataType.INT16: _INT, DataType.INT32: _INT, DataType.UINT8: _INT,
    DataType.UINT16: _INT, DataType.INT64: _LONG, DataType.UINT32: _LONG,
    DataType.UINT64: _LONG, DataType.DATETIME: _LONG, DataType.FLOAT: _FLOAT,
    DataType.DOUBLE: _DOUBLE, DataType.BOOLEAN: _BOOL, DataType.STRING: _STRING,
    DataType.TEXT: _STRING, DataType.UUID: _STRING, DataType.BYTES: _BYTES,
    DataType.FILE: _BYTES,
}  # fmt: skip
_INT_RANGE = {
    DataType.INT8: (8, True), DataType.INT16: (16, True), DataType.INT32: (32, True),
    DataType.INT64: (64, True), DataType.UINT8: (8, False), DataType.UINT16: (16, False),
    DataType.UINT32: (32, False), DataType.UINT64: (64, False), DataType.DATETIME: (64, False),
}  # fmt: skip


# -- encoding -------------------------------------------------------------------------------


def _varint(value: int, out: bytearray) -> None:
    while value > 0x7F:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)


def _key(number: int, wire: int, out: bytearray) -> None:
    _varint((number << 3) | wire, out)


def _bytes_field(number: int, data: bytes, out: bytearray) -> None:
    _key(number, _LENGTH, out)
    _varint(len(data), out)
    out += data


def _uint_field(number: int, value: int, out: bytearray) -> None:
    _key(number, _VARINT, out)
    _varint(value, out)


def _value_field(base: int, datatype: DataType, value: Value, out: bytearray) -> None:
    """``value`` in the value field of ``datatype``, field numbers counted from ``base``."""
    slot = _SLOT.get(datatype)
    if slot is None:
        raise ValueError(f"{datatype.name} values are not supported")
    number = base + slot
    if slot in (_INT, _LONG):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{datatype.name} needs an int, not {value!r}")
        bits, signed = _INT_RANGE[datatype]
        low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
        if not low <= value <= high:
            raise ValueError(f"{value} is out of range for {datatype.name}")
        _uint_field(number, value & (_U32 if slot == _INT else _U64), out)
    elif slot in (_FLOAT, _DOUBLE):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{datatype.name} needs a number, not {value!r}")
        if slot == _FLOAT:
            _key(number, _FIXED32, out)
            out += struct.pack("<f", value)
        else:
            _key(number, _FIXED64, out)
            out += struct.pack("<d", value)
    elif slot == _BOOL:
        if not isinstance(value, bool):
            raise ValueError(f"BOOLEAN needs a bool, not {value!r}")
        _uint_field(number, int(value), out)
    elif slot == _STRING:
        if not isinstance(value, str):
            raise ValueError(f"{datatype.name} needs a str, not {value!r}")
        _bytes_field(number, value.encode(), out)
    else:
        if not isinstance(value, bytes):
            raise ValueError(f"{datatype.name} needs bytes, not {value!r}")
        _bytes_field(number, value, out)


def _encode_property_set(properties: PropertySet) -> bytes:
    out = bytearray()
    for key, _ in properties.items:
        _bytes_field(_S_KEYS, key.encode(), out)
    for _, prop in properties.items:
        value = bytearray()
        _uint_field(_V_TYPE, prop.type, value)
        if prop.value is None:
            _uint_field(_V_NULL, 1, value)
        elif isinstance(prop.value, PropertySet):
            _bytes_field(_V_PROPERTY_SET, _encode_property_set(prop.value), value)
        else:
            _value_field(_V_VALUES, prop.type, prop.value, value)
        _bytes_field(_S_VALUES, bytes(value), out)
    return bytes(out)


def _encode_metric(metric: Metric) -> bytes:
    out = bytearray()
    if metric.name is not None:
        _bytes_field(_M_NAME, metric.name.encode(), out)
    if metric.alias is not None:
        _uint_field(_M_ALIAS, metric.alias, out)
    if metric.timestamp is not None:
        _uint_field(_M_TIMESTAMP, metric.timestamp, out)
    _uint_field(_M_DATATYPE, metric.datatype, out)
    if metric.is_historical:
        _uint_field(_M_HISTORICAL, 1, out)
    if metric.is_transient:
        _uint_field(_M_TRANSIENT, 1, out)
    if metric.is_null or metric.value is None:
        _uint_field(_M_NULL, 1, out)
    if metric.properties is not None:
        _bytes_field(_M_PROPERTIES, _encode_property_set(metric.properties), out)
    if metric.value is not None and not metric.is_null:
        _value_field(_M_VALUES, metric.datatype, metric.value, out)
    return bytes(out)


def encode_payload(payload: Payload) -> bytes:
    """The wire bytes of ``payload``; ValueError for a value its datatype cannot carry."""
    out = bytearray()
    if payload.timestamp is not None:
        _uint_field(_P_TIMESTAMP, payload.timestamp, out)
    for metric in payload.metrics:
        _bytes_field(_P_METRICS, _encode_metric(metric), out)
    if payload.seq is not None:
        _uint_field(_P_SEQ, payload.seq, out)
    if payload.uuid is not None:
        _bytes_field(_P_UUID, payload.uuid.encode(), out)
    if payload.body is not None:
        _bytes_field(_P_BODY, payload.body, out)
    return bytes(out)


# -- decoding -------------------------------------------------------------------------------


class _Reader:
    """Walks one message's fields: ``(number, wire type, int or bytes)`` each."""

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.at = 0

    def varint(self) -> int:
        value = shift = 0
        while True:
            if self.at >= len(self.data):
                raise ProtocolError("a varint runs past the end", raw=self.data)
            byte = self.data[self.at]
            self.at += 1
            value |= (byte & 0x7F) << shift
            if not byte & 0x80:
                return value & _U64
            shift += 7
            if shift >= 70:
                raise ProtocolError("a varint is longer than 10 bytes", raw=self.data)

    def take(self, count: int) -> bytes:
        if count > len(self.data) - self.at:
            raise ProtocolError("a field runs past the end", raw=self.data)
        chunk = self.data[self.at : self.at + count]
        self.at += count
        return chunk

    def fields(self) -> list[tuple[int, int, int | bytes]]:
        found: list[tuple[int, int, int | bytes]] = []
        while self.at < len(self.data):
            key = self.varint()
            number, wire = key >> 3, key & 7
            if number == 0:
                raise ProtocolError("field number 0", raw=self.data)
            if wire == _VARINT:
                found.append((number, wire, self.varint()))
            elif wire == _FIXED64:
                found.append((number, wire, self.take(8)))
            elif wire == _LENGTH:
                found.append((number, wire, self.take(self.varint())))
            elif wire == _FIXED32:
                found.append((number, wire, self.take(4)))
            else:
                raise ProtocolError(f"wire type {wire} is not supported", raw=self.data)
        return found


def _text(raw: int | bytes, what: str) -> str:
    if not isinstance(raw, bytes):
        raise ProtocolError(f"{what} is not length-delimited")
    try:
        return raw.decode()
    except UnicodeDecodeError as exc:
        raise ProtocolError(f"{what} is not UTF-8: {exc.reason}", raw=raw) from None


def _int(raw: int | bytes, what: str) -> int:
    if not isinstance(raw, int):
        raise ProtocolError(f"{what} is not a varint")
    return raw


def _datatype(raw: int | bytes, what: str) -> DataType:
    code = _int(raw, what)
    try:
        return DataType(code)
    except ValueError:
        raise ProtocolError(f"{what} {code} is not a Sparkplug datatype") from None


def _value(slot: int, datatype: DataType, raw: int | bytes) -> Value:
    """A value field's content as ``datatype`` says it is meant."""
    if _SLOT.get(datatype) != slot:
        raise ProtocolError(f"a {datatype.name} metric carries a value of another kind")
    if slot in (_INT, _LONG):
        number = _int(raw, "an integer value")
        bits, signed = _INT_RANGE[datatype]
        width = 32 if slot == _INT else 64
        number &= (1 << width) - 1
        if signed and number >> (width - 1):
            number -= 1 << width
        low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
        if not low <= number <= high:
            raise ProtocolError(f"{number} is out of range for {datatype.name}")
        return number
    if slot == _FLOAT:
        if not isinstance(raw, bytes) or len(raw) != 4:
            raise ProtocolError("a Float value is not 4 bytes")
        return float(struct.unpack("<f", raw)[0])
    if slot == _DOUBLE:
        if not isinstance(raw, bytes) or len(raw) != 8:
            raise ProtocolError("a Double value is not 8 bytes")
        return float(struct.unpack("<d", raw)[0])
    if slot == _BOOL:
        return bool(_int(raw, "a Boolean value"))
    if slot == _STRING:
        return _text(raw, "a string value")
    if not isinstance(raw, bytes):
        raise ProtocolError("a bytes value is not length-delimited")
    return raw


def _decode_property_set(data: bytes, depth: int) -> PropertySet:
    if depth > MAX_DEPTH:
        raise ProtocolError(f"property sets nested deeper than {MAX_DEPTH}")
    keys: list[str] = []
    values: list[PropertyValue] = []
    for number, _wire, raw in _Reader(data).fields():
        if number == _S_KEYS:
            keys.append(_text(raw, "a property key"))
        elif number == _S_VALUES:
            if not isinstance(raw, bytes):
                raise ProtocolError("a property value is not a message")
            values.append(_decode_property_value(raw, depth))
    if len(keys) != len(values):
        raise ProtocolError(f"a property set has {len(keys)} keys and {len(values)} values")
    return PropertySet(tuple(zip(keys, values, strict=True)))


def _decode_property_value(data: bytes, depth: int) -> PropertyValue:
    datatype: DataType | None = None
    is_null = False
    content: tuple[int, int | bytes] | None = None
    for number, _wire, raw in _Reader(data).fields():
        if number == _V_TYPE:
            datatype = _datatype(raw, "a property's type")
        elif number == _V_NULL:
            is_null = bool(_int(raw, "is_null"))
        elif _V_VALUES <= number <= _V_PROPERTY_SET:
            content = (number, raw)
    if datatype is None:
        raise ProtocolError("a property value has no type")
    if is_null or content is None:
        return PropertyValue(datatype, None)
    number, raw = content
    if number == _V_PROPERTY_SET:
        if datatype != DataType.PROPERTY_SET or not isinstance(raw, bytes):
            raise ProtocolError("a nested property set where its type says otherwise")
        return PropertyValue(datatype, _decode_property_set(raw, depth + 1))
    return PropertyValue(datatype, _value(number - _V_VALUES, datatype, raw))


def _decode_metric(data: bytes) -> Metric:
    fields: dict[str, object] = {}
    datatype: DataType | None = None
    content: tuple[int, int | bytes] | None = None
    for number, _wire, raw in _Reader(data).fields():
        if number == _M_NAME:
            fields["name"] = _text(raw, "a metric name")
        elif number == _M_ALIAS:
            fields["alias"] = _int(raw, "alias")
        elif number == _M_TIMESTAMP:
            fields["timestamp"] = _int(raw, "a metric timestamp")
        elif number == _M_DATATYPE:
            datatype = _datatype(raw, "a metric's datatype")
        elif number == _M_HISTORICAL:
            fields["is_historical"] = bool(_int(raw, "is_historical"))
        elif number == _M_TRANSIENT:
            fields["is_transient"] = bool(_int(raw, "is_transient"))
        elif number == _M_NULL:
            fields["is_null"] = bool(_int(raw, "is_null"))
        elif number == _M_PROPERTIES:
            if not isinstance(raw, bytes):
                raise ProtocolError("a metric's properties are not a message")
            fields["properties"] = _decode_property_set(raw, 0)
        elif _M_VALUES <= number < _M_VALUES + 7:
            content = (number, raw)
        # metadata (8), DataSet (17), Template (18), extensions: skipped
    if datatype is None:
        raise ProtocolError("a metric has no datatype")
    value = None
    if content is not None and not fields.get("is_null", False):
        value = _value(content[0] - _M_VALUES, datatype, content[1])
    return Metric(datatype=datatype, value=value, **fields)  # type: ignore[arg-type]  # typed above


def decode_payload(data: bytes) -> Payload:
    """The payload in ``data``; ProtocolError when it is not a Sparkplug B payload we read."""
    timestamp: int | None = None
    seq: int | None = None
    uuid: str | None = None
    body: bytes | None = None
    metrics: list[Metric] = []
    for number, _wire, raw in _Reader(bytes(data)).fields():
        if number == _P_TIMESTAMP:
            timestamp = _int(raw, "the timestamp")
        elif number == _P_METRICS:
            if not isinstance(raw, bytes):
                raise ProtocolError("a metric is not a message")
            metrics.append(_decode_metric(raw))
        elif number == _P_SEQ:
            seq = _int(raw, "seq")
        elif number == _P_UUID:
            uuid = _text(raw, "uuid")
        elif number == _P_BODY:
            if not isinstance(raw, bytes):
                raise ProtocolError("body is not length-delimited")
            body = raw
    return Payload(timestamp=timestamp, metrics=tuple(metrics), seq=seq, uuid=uuid, body=body)
