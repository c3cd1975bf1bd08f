"""The pipe between the daemon and its OPC UA server process: one JSON object per line.

Theory of operation
-------------------
The daemon starts the server as a child process with one end of a Unix socket pair and
writes, in order: a ``hello`` (the settings, the users, the drives and lines to show), then
``drives`` (compact drive states, only the drives that changed, conflated since the last
batch) and ``lines`` (each line up or not, its counters) as the fleet changes, and a
``result`` for each call. The child writes ``ready`` once it listens, a ``call`` for each
method a client calls (the session's user, the drive, the command's JSON) and
``sessions`` when its sessions change. Every message is a JSON object with a ``t`` naming
its kind; a line longer than :data:`MAX_LINE` or not JSON is a broken pipe, never guessed.

What goes down the pipe is only what the address space shows, so the child never needs the
daemon's classes; :func:`drive_entry` makes a drive's compact form from the public JSON
fields of a drive state (see DESIGN.md "Drive state").
"""

from __future__ import annotations

import json
from typing import Any, Final

from fcmaster.errors import FcmasterError

__all__ = ["MAX_LINE", "Decoder", "WireError", "encode"]

MAX_LINE: Final = 64 * 1024 * 1024  # a hello for 8 × 126 drives is well under 1 MiB


class WireError(FcmasterError):
    """What came down the pipe is not a message: the other side is broken."""


def encode(message: dict[str, Any]) -> bytes:
    """One message as its line (compact JSON, no NaN)."""
    return json.dumps(message, separators=(",", ":"), allow_nan=False).encode() + b"\n"


class Decoder:
    """Cuts what arrives from the pipe into messages (fed any chunks)."""

    def __init__(self, max_line: int = MAX_LINE) -> None:
        self._buffer = bytearray()
        self._max_line = max_line

    def feed(self, data: bytes) -> list[dict[str, Any]]:
        """The whole messages ``data`` completes; WireError for a line that is none."""
        self._buffer += data
        messages: list[dict[str, Any]] = []
        while True:
            end = self._buffer.find(b"\n")
            if end < 0:
                if len(self._buffer) > self._max_line:
                    raise WireError(f"a line longer than {self._max_line} bytes")
                return messages
            line = bytes(self._buffer[:end])
            del self._buffer[: end + 1]
            try:
                message = json.loads(line)
            except ValueError as exc:
                raise WireError(f"not JSON: {line[:80]!r}") from exc
            if not isinstance(message, dict) or not isinstance(message.get("t"), str):
                raise WireError(f"not a message: {line[:80]!r}")
            messages.append(message)
