"""Who holds a serial port: the message for a second opener of a port in use.

fcmaster opens local ports exclusively (pyserial's ``exclusive=True``: an ``flock`` taken
before anything about the port is changed), so a second opener — another daemon, a
commissioning command while the daemon runs — fails before it can touch the line's
settings or bytes. Linux lists every ``flock`` in ``/proc/locks`` with the holder's PID and
the locked file's device and inode; that names the holder. Elsewhere the message says only
that the port is in use.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path

import serial

_REFUSED = {errno.EWOULDBLOCK, errno.EAGAIN}


def lock_refused(exc: BaseException) -> bool:
    """Whether opening failed because another process holds the port's lock."""
    return isinstance(exc, serial.SerialException) and getattr(exc, "errno", None) in _REFUSED


def in_use_message(port: str, *, locks: Path = Path("/proc/locks")) -> str:
    """``port … is in use by PID n (command)``, naming the holder where the system tells."""
    holders = _holders(port, locks)
    if not holders:
        return f"port {port} is in use by another program"
    named = ", ".join(f"PID {pid} ({_command(pid)})" for pid in holders)
    return f"port {port} is in use by {named}"


def _holders(port: str, locks: Path) -> list[int]:
    try:
        node = os.stat(port)
        table = locks.read_text(encoding="ascii", errors="replace")
    except OSError:
        return []
    wanted = (os.major(node.st_dev), os.minor(node.st_dev), node.st_ino)
    found: list[int] = []
    for line in table.splitlines():
        # "1: FLOCK  ADVISORY  WRITE 4242 00:1a:1234 0 EOF" (blocked waiters have "->")
        fields = line.split()
        if len(fields) < 6 or fields[1] != "FLOCK" or "->" in fields:
            continue
        try:
            pid = int(fields[4])
            major, minor, inode = fields[5].split(":")
            where = (int(major, 16), int(minor, 16), int(inode))
        except ValueError:
            continue
        if where == wanted and pid != os.getpid() and pid not in found:
            found.append(pid)
    return found


def _command(pid: int) -> str:
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return "gone"
    words = [w.decode(errors="replace") for w in raw.split(b"\0") if w]
    text = " ".join(Path(words[0]).name if i == 0 else w for i, w in enumerate(words))
    return text if len(text) <= 80 else text[:79] + "…"
