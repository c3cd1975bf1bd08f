"""A readable account of one captured ENC frame, for `fcmaster decode` and for logs.

Keys of every account: ``direction``, ``address``, ``address_field``,
``address_readings``, ``broadcast``, ``command``, ``aux_index``, ``cmd_index``, ``index``,
``data``, ``checksum``, ``checksum_ok`` (and ``checksum_expected`` when it is not).
``command`` is the second field read as hex: the command (10-15) of a request, the raw
response field of a reply. A request adds ``command_name`` and, by command, ``parameter``,
``parameter_name``, ``action``, ``frequency_hz`` and ``value``. A reply adds ``response``
(the code as the manual prints it), ``response_field``, ``response_readings``,
``response_text``, ``failure_index`` (the fault code) and ``fault``. A reply does not say
what it answers, so its data is shown raw.

``address`` and ``response`` take the line's reading where a field has two (see
:mod:`fcmaster.protocol.enc.codes`); ``*_readings`` shows both.
"""

from __future__ import annotations

from typing import Any

from fcmaster.errors import ProtocolError, UsageError
from fcmaster.protocol.enc.codes import (
    fault_text,
    number_encoding,
    read_fault,
    read_response,
    readings,
    response_text,
)
from fcmaster.protocol.enc.frame import (
    BROADCAST,
    RUN_CONTROL_WITH_DATA,
    Command,
    RunControl,
    checksum,
    split_frame,
)
from fcmaster.protocol.enc.parameters import format_parameter, lookup, make_code


def describe_frame(
    frame: bytes,
    *,
    from_drive: bool,
    address_encoding: str = "hex",
    response_encoding: str = "hex",
    fault_encoding: str = "hex",
) -> dict[str, Any]:
    """Decode every field of ``frame`` into JSON-ready values.

    A wrong checksum does not stop the decode (``checksum_ok`` is then false), but a frame
    whose structure is broken (no ``~`` or CR, a character that is not an uppercase hex
    digit, a length no frame has) raises UsageError. The encodings are the line options of
    :class:`~fcmaster.protocol.enc.codec.EncCodec`; they decide ambiguous fields only.
    """
    try:
        body, sent, checksum_ok = split_frame(frame)
    except ProtocolError as exc:
        raise UsageError(str(exc)) from None
    lengths = (4, 8, 12) if from_drive else (8, 12)
    if len(body) not in lengths:
        raise UsageError(
            f"{'a reply' if from_drive else 'a request'} has "
            f"{' or '.join(str(n) for n in lengths)} characters between ~ and the checksum, "
            f"not {len(body)}"
        )
    fields = [int(body[i : i + 2], 16) for i in range(0, min(len(body), 8), 2)]
    address_field, second = fields[0], fields[1]
    aux_index = fields[2] if len(fields) > 2 else None
    cmd_index = fields[3] if len(fields) > 3 else None
    data = int(body[8:12], 16) if len(body) == 12 else None
    address = readings(address_field).get(number_encoding(address_encoding), address_field)
    out: dict[str, Any] = {
        "direction": "response" if from_drive else "request",
        "address": address,
        "address_field": f"{address_field:02X}",
        "address_readings": _readings(address_field),
        "broadcast": address_field == BROADCAST,
        "command": second,
        "aux_index": aux_index,
        "cmd_index": cmd_index,
        "index": None if cmd_index is None else f"{aux_index:02X}{cmd_index:02X}",
        "data": data,
        "checksum": sent,
        "checksum_ok": checksum_ok,
    }
    if not checksum_ok:
        out["checksum_expected"] = checksum(body)
    if from_drive:
        out.update(_reply(second, aux_index, cmd_index, response_encoding, fault_encoding))
    else:
        out.update(_request(second, aux_index or 0, cmd_index or 0, data))
    return out


def _request(command: int, aux_index: int, cmd_index: int, data: int | None) -> dict[str, Any]:
    out: dict[str, Any] = {"command_name": _name(Command, command)}
    index = aux_index << 8 | cmd_index
    if command == Command.RUN_CONTROL:
        out["action"] = None if aux_index else _name(RunControl, cmd_index)
        if not aux_index and cmd_index in RUN_CONTROL_WITH_DATA and data is not None:
            out["frequency_hz"] = data / 100
    elif command in (Command.LOOK_UP_STATE, Command.READ_VALUE, Command.SOFTWARE_VERSION):
        code = make_code(command, index)
        out["parameter"] = format_parameter(code)
        out["parameter_name"] = lookup(code).name or None
    elif command in (Command.READ_PARAMETER, Command.WRITE_PARAMETER):
        code = make_code(Command.READ_PARAMETER, index)
        spec = lookup(code)
        out["parameter"] = format_parameter(code)
        out["parameter_name"] = spec.name or None
        if command == Command.WRITE_PARAMETER and data is not None:
            out["value"] = {"raw": data, "value": spec.to_value(data), "unit": spec.unit}
    return out


def _reply(
    field: int,
    failure_field: int | None,
    cmd_index: int | None,
    response_encoding: str,
    fault_encoding: str,
) -> dict[str, Any]:
    try:
        code: int | None = read_response(
            field, None, number_encoding(response_encoding), has_index=cmd_index is not None
        )
    except ProtocolError:
        code = None
    fault = (
        None
        if failure_field is None
        else read_fault(failure_field, number_encoding(fault_encoding))
    )
    return {
        "response": code,
        "response_field": f"{field:02X}",
        "response_readings": _readings(field),
        "response_text": None if code is None else response_text(code),
        "failure_index": fault,
        "fault": None if not fault else fault_text(fault),
    }


def _readings(field: int) -> dict[str, int]:
    return {str(encoding): value for encoding, value in readings(field).items()}


def _name(names: type[Command] | type[RunControl], value: int) -> str | None:
    try:
        return names(value).name.lower()
    except ValueError:
        return None
