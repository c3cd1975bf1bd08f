"""Checks of single config values: port URLs, and names that every surface can address."""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any
from urllib.parse import urlsplit

if TYPE_CHECKING:
    from fcmaster.protocol.spec import ProtocolSpec

# Port URLs the master can drive: the simulator, serial device servers (raw TCP, RFC 2217)
# and pyserial's local helpers; anything else would fail only when the line first opens.
_PORT_SCHEMES = ("sim", "socket", "rfc2217", "loop", "spy", "hwgrep", "alt")


# Something that starts like a URL (``socket:/host:4001``, ``rfc2217:host``) but lacks its
# ``://``: a scheme of two or more letters (one letter is a Windows drive, ``C:\\``) then ':'.
_SCHEME_ONLY = re.compile(r"([A-Za-z][A-Za-z0-9+.-]+):(?!//)")


def port_url_problem(port: str) -> str:
    """What is wrong with a port URL ("" for a device path or a URL the master can open)."""
    if not port.strip():
        return "is empty: give a device path or a URL"
    scheme, separator, _rest = port.partition("://")
    if not separator:
        malformed = _SCHEME_ONLY.match(port)
        if malformed and malformed[1].lower() in _PORT_SCHEMES:
            return f"{port!r} is not a well-formed URL: write {malformed[1]}://host:port"
        if malformed:
            return f"{port!r} is neither a device path nor a URL (scheme://…)"
        return ""
    if scheme not in _PORT_SCHEMES:
        listed = ", ".join(f"{s}://" for s in _PORT_SCHEMES)
        return f"{scheme}:// is not a port this master can open (use a device path or {listed})"
    if scheme in ("socket", "rfc2217"):
        try:
            parts = urlsplit(port)
            if not parts.hostname or parts.port is None:
                raise ValueError
        except ValueError:
            return f"use {scheme}://host:port (got {port!r})"
    return ""


def baudrate_problem(spec: ProtocolSpec[Any], baudrate: int) -> str:
    """Why ``baudrate`` is not one the protocol's drives offer (as config and CLI say it)."""
    offered = ", ".join(str(rate) for rate in sorted(spec.baudrates))
    return f"{baudrate} is not a baud rate {spec.name} drives offer ({offered})"


_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")


def check_name(name: str, path: str, problems: list[tuple[str, str]]) -> None:
    """A drive or bus name every surface can address: no /, +, #, %, spaces, ``..``."""
    if not _NAME.fullmatch(name):
        problems.append(
            (
                path,
                f"{name!r} cannot be addressed over HTTP and MQTT: use 1-64 letters, digits, "
                "'-', '_' and '.', starting with a letter or digit",
            )
        )
