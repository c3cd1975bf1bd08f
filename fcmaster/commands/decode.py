"""`fcmaster decode`: explain a captured frame field by field."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

from fcmaster.commands.frames import parse_hex
from fcmaster.errors import UsageError
from fcmaster.protocol.danfoss_fc import describe_telegram
from fcmaster.protocol.enc.describe import describe_frame as describe_enc
from fcmaster.protocol.mitsubishi.describe import describe_frame as describe_mitsubishi
from fcmaster.protocol.mitsubishi.notation import parse_ascii_frame

# protocol → (describe, the key that says whether the checksum held)
_DESCRIBE: dict[str, tuple[Callable[..., dict[str, Any]], str]] = {
    "danfoss-fc": (describe_telegram, "bcc_ok"),
    "mitsubishi": (describe_mitsubishi, "sum_ok"),
    "enc": (describe_enc, "checksum_ok"),
}


def run(protocol: str, frame_text: str, *, as_response: bool, as_json: bool) -> int:
    """Print the decode; return 0, or 1 when the checksum is wrong."""
    if protocol not in _DESCRIBE:
        raise UsageError(f"unknown protocol {protocol!r}")
    describe, checksum_key = _DESCRIBE[protocol]
    decoded = describe(read_frame(frame_text), from_drive=as_response)
    print(json.dumps(decoded, indent=2) if as_json else _table(decoded))
    return 0 if decoded[checksum_key] else 1


def read_frame(text: str) -> bytes:
    """Hex bytes, or ASCII with control characters written <ENQ>, <CR>, … (ASCII protocols)."""
    if "<" in text or "~" in text:
        return parse_ascii_frame(text.strip())
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
