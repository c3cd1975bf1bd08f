"""Frames written the way the manuals and users write them: ``<ENQ>01E1107ADF4<CR>``.

Control characters are named in angle brackets, case-insensitive: the seven of §3 (STX,
ETX, ENQ, ACK, NAK, CR, LF). Any other byte can be written ``<0x1B>``. Printable ASCII
characters stand for themselves, spaces included (the model name has them), so write the
hex fields without separators.
"""

from __future__ import annotations

import re
from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.mitsubishi.message import ACK, CR, ENQ, ETX, LF, NAK, STX

CONTROL_NAMES: Final[dict[str, int]] = {
    "STX": STX,
    "ETX": ETX,
    "ENQ": ENQ,
    "ACK": ACK,
    "NAK": NAK,
    "CR": CR,
    "LF": LF,
}
_NAMES_BY_BYTE: Final = {code: name for name, code in CONTROL_NAMES.items()}
_TOKEN = re.compile(r"<([A-Za-z]+|0[xX][0-9A-Fa-f]{2})>")


def parse_ascii_frame(text: str) -> bytes:
    """The bytes of ``text`` with ``<NAME>`` tokens replaced by their control characters.

    Raises UsageError for an unknown name or a character that is neither printable ASCII
    nor written as a token.
    """
    out = bytearray()
    pos = 0
    while pos < len(text):
        match = _TOKEN.match(text, pos)
        if match:
            token = match[1]
            if token[:2].lower() == "0x":
                out.append(int(token[2:], 16))
            else:
                code = CONTROL_NAMES.get(token.upper())
                if code is None:
                    known = ", ".join(f"<{name}>" for name in CONTROL_NAMES)
                    raise UsageError(f"<{token}> is not a control character name ({known})")
                out.append(code)
            pos = match.end()
            continue
        char = text[pos]
        if not " " <= char <= "~":
            raise UsageError(
                f"character {char!r} at position {pos} is not printable ASCII; "
                "write control characters as <ENQ>, <CR>, …"
            )
        out.append(ord(char))
        pos += 1
    if not out:
        raise UsageError("no frame given: write it like <ENQ>01E1107ADF4<CR>")
    return bytes(out)


def format_ascii_frame(frame: bytes) -> str:
    """``frame`` written with ``<NAME>`` tokens: the inverse of :func:`parse_ascii_frame`."""
    parts = []
    for byte in frame:
        if byte in _NAMES_BY_BYTE:
            parts.append(f"<{_NAMES_BY_BYTE[byte]}>")
        elif 0x20 <= byte <= 0x7E and byte != ord("<"):
            parts.append(chr(byte))
        else:
            parts.append(f"<0x{byte:02X}>")
    return "".join(parts)
