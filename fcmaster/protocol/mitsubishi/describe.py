"""A readable account of one captured computer-link frame, for `fcmaster decode` and logs.

Frames say what they are by their first character, so the account does not depend on the
direction given, except for ACK, whose shape is the same both ways (a drive accepting a
write, or the master confirming a read reply). A data reply does not name the instruction
it answers, so its data is shown raw.
"""

from __future__ import annotations

from typing import Any

from fcmaster.errors import MalformedReply, UsageError
from fcmaster.protocol.mitsubishi.error_codes import error_text
from fcmaster.protocol.mitsubishi.instructions import (
    BY_CODE,
    INVERTER_RESET,
    LINK_PAGE,
    RESET_AFTER_ACK,
    RESET_NO_REPLY,
    RUN_COMMAND,
    SET_FREQUENCY_EEPROM,
    SET_FREQUENCY_RAM,
    describe_code,
)
from fcmaster.protocol.mitsubishi.message import (
    Ack,
    DataReply,
    Nak,
    Request,
    decode_frame,
    encode_frame,
    split_terminator,
)
from fcmaster.protocol.mitsubishi.notation import format_ascii_frame
from fcmaster.protocol.mitsubishi.profile import (
    OperationMode,
    RunCommand,
    flag_names,
    frequency_hz,
)

_MULTI_COMMAND = 0xF0
_MULTI_REPLY_WIDTH = 12


def describe_frame(frame: bytes, *, from_drive: bool) -> dict[str, Any]:
    """Decode every field of ``frame`` into JSON-ready values.

    A wrong sum check does not stop the decode (``sum_ok`` is then false and
    ``sum_expected`` holds the right one); frames without a sum check (ACK, NAK) have
    ``sum`` null and ``sum_ok`` true. A frame whose structure is broken raises UsageError.
    """
    try:
        message = decode_frame(frame, check_sum=False)
    except MalformedReply as exc:
        raise UsageError(f"not a Mitsubishi computer-link frame: {exc}") from None
    body, terminator = split_terminator(frame)
    canonical = encode_frame(message, terminator)
    has_sum = isinstance(message, Request | DataReply)
    out: dict[str, Any] = {
        "protocol": "mitsubishi",
        "frame": _FRAME_NAMES[type(message)],
        "direction": _direction(message, from_drive),
        "station": message.station,
        "instruction": None,
        "instruction_name": None,
        "access": None,
        "wait_ms": None,
        "width": None,
        "data": None,
        "error_code": None,
        "sum": body[-2:].decode("ascii") if has_sum else None,
        "sum_ok": canonical == frame,
        "terminator": terminator.value,
        "ascii": format_ascii_frame(frame),
    }
    if canonical != frame:
        out["sum_expected"] = split_terminator(canonical)[0][-2:].decode("ascii")
    if isinstance(message, Request):
        out.update(
            instruction=f"{message.instruction:02X}",
            instruction_name=describe_code(message.instruction),
            access="read" if message.is_read else "write",
            wait_ms=message.wait_ms,
            width=message.width,
            data=message.data,
        )
        if message.data is not None:
            out.update(_request_meaning(message.instruction, message.data))
    elif isinstance(message, DataReply):
        out.update(width=message.width, data=message.data)
        if message.text is not None:
            out["text"] = message.text
        elif message.width == _MULTI_REPLY_WIDTH and message.data is not None:
            out["multi_command"] = _multi_reply(message.data)
    elif isinstance(message, Nak) and message.error_code is not None:
        out.update(error_code=message.error_code, error_text=error_text(message.error_code))
    return out


_FRAME_NAMES: dict[type, str] = {
    Request: "request",
    DataReply: "data_reply",
    Ack: "ack",
    Nak: "nak",
}


def _direction(message: Request | DataReply | Ack | Nak, from_drive: bool) -> str:
    if isinstance(message, Request):
        return "request"
    if isinstance(message, DataReply):
        return "response"
    if isinstance(message, Nak):
        return "response" if message.error_code is not None else "request"
    return "response" if from_drive else "request"


def _request_meaning(instruction: int, data: int) -> dict[str, Any]:
    if instruction == RUN_COMMAND.code:
        return {"run_command": flag_names(data, RunCommand)}
    if instruction in (SET_FREQUENCY_RAM.write, SET_FREQUENCY_EEPROM.write):
        return {"frequency_hz": frequency_hz(data)}
    if instruction == INVERTER_RESET.code:
        replies = {RESET_NO_REPLY: "no reply", RESET_AFTER_ACK: "ACK, then reset"}
        return {"reset": replies.get(data, "not a reset code")}
    if instruction == LINK_PAGE.write:
        return {"page": data}
    if instruction == BY_CODE[0x7B].write:
        names = {int(mode): mode.name.lower() for mode in OperationMode}
        return {"operation_mode": names.get(data, "unknown")}
    if instruction == _MULTI_COMMAND:
        return {
            "multi_command": {
                "send_type": data >> 36,
                "reply_type": (data >> 32) & 0xF,
                "data1": (data >> 16) & 0xFFFF,
                "data2": data & 0xFFFF,
            }
        }
    return {}


def _multi_reply(data: int) -> dict[str, int]:
    # §9.1 C1: s r e1 e2 data1(4) data2(4), one hex digit each for s, r, e1, e2.
    return {
        "send_type": data >> 44,
        "reply_type": (data >> 40) & 0xF,
        "error_code_1": (data >> 36) & 0xF,
        "error_code_2": (data >> 32) & 0xF,
        "data1": (data >> 16) & 0xFFFF,
        "data2": data & 0xFFFF,
    }
