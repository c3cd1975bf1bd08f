"""A readable account of one captured FC telegram, for `fcmaster decode` and for logs."""

from __future__ import annotations

from typing import Any

from fcmaster.errors import ProtocolError, UsageError
from fcmaster.protocol.danfoss_fc.error_codes import error_text
from fcmaster.protocol.danfoss_fc.parameters import DataType, format_parameter, lookup
from fcmaster.protocol.danfoss_fc.profile import (
    ControlWord,
    StatusWord,
    decode_reference,
    flag_names,
)
from fcmaster.protocol.danfoss_fc.telegram import (
    STX,
    RequestAk,
    ResponseAk,
    bcc,
    decode_telegram,
)

_VALUE_REQUESTS = (
    RequestAk.WRITE_WORD,
    RequestAk.WRITE_DWORD,
    RequestAk.WRITE_WORD_EEPROM,
    RequestAk.WRITE_DWORD_EEPROM,
)


def describe_telegram(frame: bytes, *, from_drive: bool) -> dict[str, Any]:
    """Decode every field of ``frame`` into JSON-ready values.

    A wrong BCC does not stop the decode (``bcc_ok`` is then false), but a frame whose
    structure is broken (no STX, a length that does not match) raises UsageError.
    """
    if len(frame) < 2 or frame[0] != STX:
        raise UsageError("an FC telegram starts with STX (02)")
    if frame[1] + 2 != len(frame):
        raise UsageError(
            f"LGE {frame[1]} says the telegram is {frame[1] + 2} bytes long, but "
            f"{len(frame)} were given"
        )
    bcc_ok = bcc(frame) == 0
    checked = frame if bcc_ok else frame[:-1] + bytes((bcc(frame[:-1]),))
    try:
        telegram = decode_telegram(checked, from_drive=from_drive)
    except ProtocolError as exc:
        raise UsageError(str(exc)) from exc

    out: dict[str, Any] = {
        "direction": "response" if from_drive else "request",
        "address": telegram.address,
        "address_format": int(telegram.address_format),
        "broadcast": telegram.is_broadcast,
        "telegram": "process" if telegram.pke is None else "parameter",
        "ak": None,
        "ak_name": None,
        "parameter": None,
        "parameter_name": None,
        "pnu": None,
        "index": None,
        "pwe": None,
        "pcd1": telegram.pcd1,
        "pcd2": telegram.pcd2,
        "bcc": frame[-1],
        "bcc_ok": bcc_ok,
    }
    if not bcc_ok:
        out["bcc_expected"] = checked[-1]
    if telegram.pke is not None:
        ak, pnu = telegram.ak, telegram.pnu
        spec = lookup(pnu)
        names: type[ResponseAk] | type[RequestAk] = ResponseAk if from_drive else RequestAk
        known = {int(member): member.name.lower() for member in names}
        out.update(
            ak=ak,
            ak_name=known.get(ak, "unknown"),
            parameter=format_parameter(pnu),
            parameter_name=spec.name or None,
            pnu=pnu,
            index=telegram.ind,
            pwe=None if telegram.text is not None else telegram.pwe,
        )
        if telegram.text is not None:
            out["telegram"] = "text"
            out["text"] = telegram.text.decode("latin-1")
        elif from_drive and ak == ResponseAk.ERROR:
            code = telegram.pwe & 0xFFFF
            out["error"] = {"code": code, "text": error_text(code)}
        elif spec.data_type is not DataType.TEXT and (
            (from_drive and ak in (ResponseAk.VALUE_WORD, ResponseAk.VALUE_DWORD))
            or (not from_drive and ak in _VALUE_REQUESTS)
        ):
            double_word = ak in (
                (ResponseAk.VALUE_DWORD,)
                if from_drive
                else (RequestAk.WRITE_DWORD, RequestAk.WRITE_DWORD_EEPROM)
            )
            try:
                raw = spec.raw_from_pwe(telegram.pwe, double_word=double_word)
            except ProtocolError as exc:
                # A capture may hold a PWE its data type cannot carry: show why, not a value.
                out["value_error"] = str(exc)
            else:
                out["value"] = {"raw": raw, "value": spec.to_value(raw), "unit": spec.unit}
    if from_drive:
        out["status"] = flag_names(telegram.pcd1, StatusWord)
        out["output_pct"] = decode_reference(telegram.pcd2)
    else:
        out["control"] = flag_names(telegram.pcd1, ControlWord)
        out["reference_pct"] = decode_reference(telegram.pcd2)
    return out
