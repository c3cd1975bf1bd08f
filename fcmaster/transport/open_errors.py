"""Why a port did not open, said once and with the fix that applies to it.

pyserial wraps the operating system's error in its own, so its text repeats the errno and
the path ("could not open port X: [Errno 2] No such file or directory: 'X'"). This finds
the errno underneath and turns it into one reason and, where there is one, the usual fix:
the dialout group only for a local device the user may not open, never for a network URL.
"""

from __future__ import annotations

import errno
import os
import termios

# errno → the fix, for a local device path
_DEVICE_HINTS = {
    errno.ENOENT: "check the device path; `fcmaster ports` lists the serial adapters here",
    errno.EACCES: "this user may not open it: add the user to the dialout group, log in again",
    errno.EPERM: "this user may not open it: add the user to the dialout group, log in again",
    errno.EBUSY: "another program has it open",
    errno.ENOTTY: "it is not a serial port",
    errno.ENXIO: "the device is gone (unplugged?)",
    errno.ENODEV: "the device is gone (unplugged?)",
}
# errno → the fix, for socket:// and rfc2217:// URLs
_NETWORK_HINTS = {
    errno.ECONNREFUSED: "nothing listens at that host and port",
    errno.ETIMEDOUT: "the host did not answer",
    errno.EHOSTUNREACH: "the host cannot be reached",
    errno.ENETUNREACH: "the network cannot be reached",
}


def open_error(port: str, exc: BaseException) -> str:
    """``cannot open PORT: REASON (FIX)`` for ``exc``, raised while opening ``port``."""
    code = _errno(exc)
    reason = os.strerror(code).lower() if code is not None else str(exc)
    if code is not None and code < 0:  # getaddrinfo's codes (EAI_*), not the system's
        return f"cannot open {port}: the host name or address cannot be resolved"
    hints = _NETWORK_HINTS if "://" in port else _DEVICE_HINTS
    hint = hints.get(code) if code is not None else None
    return f"cannot open {port}: {reason}" + (f" ({hint})" if hint else "")


def _errno(exc: BaseException) -> int | None:
    """The operating system's error number in ``exc`` or the errors it wraps."""
    seen: BaseException | None = exc
    while seen is not None:
        number = getattr(seen, "errno", None)
        if isinstance(number, int):
            return number
        if isinstance(seen, termios.error) and seen.args and isinstance(seen.args[0], int):
            return int(seen.args[0])
        seen = seen.__cause__ or seen.__context__
    return None
