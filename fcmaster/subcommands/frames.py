"""Reading frames the way users paste them: hex bytes, or ASCII with <CR>-style names."""

from __future__ import annotations

import re

from fcmaster.errors import UsageError

_SEPARATORS = re.compile(r"[\s:,]+")


def parse_hex(text: str) -> bytes:
    """Bytes from hex digits; spaces, colons and commas between bytes are ignored."""
    digits = "".join(_strip_0x(part) for part in _SEPARATORS.split(text.strip()))
    if not digits:
        raise UsageError("no frame given: write it as hex bytes, e.g. 02 06 81 04 7C 20 00 D9")
    if len(digits) % 2:
        raise UsageError(f"odd number of hex digits ({len(digits)}): a byte is two digits")
    try:
        return bytes.fromhex(digits)
    except ValueError:
        bad = next(ch for ch in digits if ch not in "0123456789abcdefABCDEF")
        raise UsageError(f"{bad!r} is not a hex digit") from None


def _strip_0x(part: str) -> str:
    return part[2:] if part[:2].lower() == "0x" else part
