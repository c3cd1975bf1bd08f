"""`fcmaster decode`: explain a captured frame field by field."""

from __future__ import annotations

import json
from typing import Any

from fcmaster.errors import UsageError
from fcmaster.protocol.registry import PROTOCOLS
from fcmaster.protocol.spec import ProtocolSpec
from fcmaster.subcommands.frames import parse_hex


def run(protocol: str, frame_text: str, *, as_response: bool, as_json: bool) -> int:
    """Print the decode; return 0, or 1 when the checksum is wrong."""
    spec = PROTOCOLS.get(protocol)
    if spec is None:
        raise UsageError(f"unknown protocol {protocol!r}")
    decoded = spec.describe(read_frame(frame_text, spec), from_drive=as_response)
    print(json.dumps(decoded, indent=2) if as_json else _table(decoded))
    return 0 if decoded[spec.checksum_key] else 1


def read_frame(text: str, spec: ProtocolSpec[Any]) -> bytes:
    """Hex bytes, or ASCII with control characters written <ENQ>, <CR>, ….

    The ASCII notation is read where ``spec``'s protocol has one (the ASCII protocols).
    """
    if spec.parse_text is not None and ("<" in text or "~" in text):
        return spec.parse_text(text.strip())
    return parse_hex(text)


def _table(decoded: dict[str, Any]) -> str:
    width = max([16, *(len(key) + 2 for key in decoded)])  # a long key keeps a gap too
    lines = []
    for key, value in decoded.items():
        if isinstance(value, dict) and key in ("control", "status"):
            active = [name for name, on in value.items() if on]
            lines.append(f"{key:<{width}}{', '.join(active) or '(none)'}")
        elif isinstance(value, dict):
            lines.append(f"{key:<{width}}{', '.join(f'{k}={v}' for k, v in value.items())}")
        elif value is not None:
            lines.append(f"{key:<{width}}{_hex_if_word(key, value)}")
    return "\n".join(lines)


def _hex_if_word(key: str, value: object) -> str:
    if key in ("pcd1", "pcd2", "index") and isinstance(value, int):
        return f"0x{value:04X} ({value})"
    if key in ("pwe",) and isinstance(value, int):
        return f"0x{value:08X} ({value})"
    if key in ("bcc", "bcc_expected") and isinstance(value, int):
        return f"0x{value:02X}"
    return str(value)
