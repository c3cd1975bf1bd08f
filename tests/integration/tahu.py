"""Eclipse Tahu's JavaScript Sparkplug B codec (npm ``sparkplug-payload``) as a peer decoder.

``tests/node/sparkplug`` holds it, pinned (``npm ci`` there; .ci/run does it). Without node
or the installed package a test is skipped, except under ``CI=true``, where it fails.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest

from fcmaster.adapters.sparkplug.payload import (
    DataType,
    Metric,
    Payload,
    PropertySet,
    PropertyValue,
    Value,
)

FOLDER = Path(__file__).resolve().parent.parent / "node" / "sparkplug"
TIMEOUT_S = 60.0


def tahu_marks() -> list[pytest.MarkDecorator]:
    """A module's marks: none when Tahu's codec is installed, else a skip; under CI, an error."""
    node = shutil.which("node")
    if node is not None and (FOLDER / "node_modules" / "sparkplug-payload").is_dir():
        return []
    why = f"needs node and `npm ci` in {FOLDER}"
    if os.environ.get("CI") == "true":
        raise RuntimeError(f"the Sparkplug peer tests {why}")
    return [pytest.mark.skip(reason=why)]


def tahu_decode(payloads: list[bytes]) -> list[dict[str, Any]]:
    """Each payload as Tahu's ``decodePayload`` reads it, as JSON (Longs as decimal strings)."""
    done = subprocess.run(
        ["node", str(FOLDER / "decode.js")],
        input="".join(p.hex() + "\n" for p in payloads),
        capture_output=True, text=True, check=True, timeout=TIMEOUT_S,
    )  # fmt: skip
    # Not splitlines: U+2028 is text. Every integer Tahu prints as a number has 32 bits (64-bit
    # ones are strings), so a longer one is a Float or Double that JavaScript printed whole.
    decoded = [json.loads(line, parse_int=_number) for line in done.stdout.split("\n") if line]
    assert len(decoded) == len(payloads), done.stderr
    return decoded


def _number(text: str) -> int | float:
    value = int(text)
    return float(value) if abs(value) >= 1 << 53 else value


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
