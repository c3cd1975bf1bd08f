"""`fcmaster decode`: explain a captured frame field by field."""

from __future__ import annotations

import json
from typing import Any

from fcmaster.commands.frames import parse_hex
from fcmaster.errors import UsageError
from fcmaster.protocol.danfoss_fc import describe_telegram


def run(protocol: str, frame_text: str, *, as_response: bool, as_json: bool) -> int:
    """Print the decode; return 0, or 1 when the checksum is wrong."""
    if protocol != "danfoss-fc":
        raise UsageError(f"decoding {protocol} frames is not supported yet")
    decoded = describe_telegram(parse_hex(frame_text), from_drive=as_response)
    print(json.dumps(decoded, indent=2) if as_json else _table(decoded))
    return 0 if decoded["bcc_ok"] else 1


def _table(decoded: dict[str, Any]) -> str:
    lines = []
    for key, value in decoded.items():
        if isinstance(value, dict) and key in ("control", "status"):
            active = [name for name, on in value.items() if on]
            lines.append(f"{key:<16}{', '.join(active) or '(none)'}")
        elif isinstance(value, dict):
            lines.append(f"{key:<16}{', '.join(f'{k}={v}' for k, v in value.items())}")
        elif value is not None:
            lines.append(f"{key:<16}{_hex_if_word(key, value)}")
    return "\n".join(lines)


def _hex_if_word(key: str, value: object) -> str:
    if key in ("pcd1", "pcd2", "index") and isinstance(value, int):
        return f"0x{value:04X} ({value})"
    if key in ("pwe",) and isinstance(value, int):
        return f"0x{value:08X} ({value})"
    if key in ("bcc", "bcc_expected") and isinstance(value, int):
        return f"0x{value:02X}"
    return str(value)
