"""``fcmaster decode --protocol modbus-rtu``: every field of a captured RTU frame."""

from __future__ import annotations

from typing import Any

from fcmaster.errors import MalformedReply, UsageError
from fcmaster.protocol.modbus_rtu.crc import crc_ok, with_crc
from fcmaster.protocol.modbus_rtu.exception_codes import exception_text
from fcmaster.protocol.modbus_rtu.frame import (
    ExceptionReply,
    ReadRequest,
    Registers,
    WriteMultiple,
    WriteSingle,
    Written,
    decode_request,
    decode_response,
)


def describe_frame(frame: bytes, *, from_drive: bool) -> dict[str, Any]:
    """The fields of ``frame`` (a drive's answer with ``from_drive``), JSON-ready.

    A wrong CRC does not stop the decode (``crc_ok`` is then false); a frame whose fields
    disagree raises UsageError saying how.
    """
    if len(frame) < 4:
        raise UsageError(f"{len(frame)} bytes are too short for an RTU frame")
    ok = crc_ok(frame)
    checked = frame if ok else _with_right_crc(frame)
    try:
        message = decode_response(checked) if from_drive else decode_request(checked)
    except MalformedReply as exc:
        raise UsageError(str(exc)) from None
    out: dict[str, Any] = {
        "address": frame[0],
        "broadcast": frame[0] == 0,
        "function": frame[1],
        "crc": f"{frame[-2] | frame[-1] << 8:04X}",
        "crc_ok": ok,
    }
    match message:
        case ReadRequest(start=start, count=count):
            out |= {"start": start, "count": count}
        case WriteSingle(register=register, value=value):
            out |= {"register": register, "value": value}
        case WriteMultiple(start=start, values=values):
            out |= {"start": start, "values": list(values)}
        case Registers(values=values):
            out |= {"values": list(values)}
        case Written(start=start, count=count):
            out |= {"start": start, "count": count}
        case ExceptionReply(function=function, code=code):
            out |= {"function": function, "exception": code, "text": exception_text(code)}
    return out


def _with_right_crc(frame: bytes) -> bytes:
    return with_crc(frame[:-2])
