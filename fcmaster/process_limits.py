"""What the daemon asks of its process: open files it can use, errors said once.

The open-file limit the event loop can use, and a log of the loop's errors that says a
repeated error once, with a count.

Theory of operation
-------------------
**Open files.** Every connection and port is a file descriptor. The daemon's loop waits in
``select()`` (:mod:`fcmaster.clock`), which handles descriptors below
:data:`FD_SETSIZE` only: a descriptor of 1024 or more would make ``select()`` fail and stop
the loop, every line with it. So the soft limit is set to the hard one where that is below
1024, and to 1024 where it is above (Docker's default is 1,048,576): running out of
descriptors is then an error a connection gets (``EMFILE``), never one the loop dies of.
:func:`fit_file_limit` does that and says what it found and set (``process.file_limit``),
and :func:`connection_budget` tells the servers how many connections fit, leaving
:data:`FD_HEADROOM` for the lines, the journal, the MQTT session and what was just accepted
and is being closed, so that the HTTP guard's reserve for stops always has descriptors.

**Errors that repeat.** asyncio's accept loop, out of descriptors, reports the error once
per connection waiting in the backlog and again each second it retries (the log grew
151 MB in 32 s in a test). :class:`RepeatedErrors` is the loop's exception handler: the
first of a kind (its message and exception type) is logged with its traceback; the rest
within :data:`REPEAT_WINDOW_S` are counted and logged as one line at the window's end
(``loop.error_repeated``, ``count``).
"""

from __future__ import annotations

import asyncio
from typing import Any, Final

import structlog

log = structlog.get_logger("fcmaster.process")

FD_SETSIZE: Final = 1024  # select() waits on descriptors below this
FD_HEADROOM: Final = 160  # kept for lines, files, sessions and connections being closed
REPEAT_WINDOW_S: Final = 60.0


def fit_file_limit() -> tuple[int, int] | None:
    """Set the soft open-file limit to what the loop can use; the soft and hard limits.

    None where the platform has no such limit (Windows).
    """
    try:
        import resource
    except ImportError:  # pragma: no cover - not POSIX
        return None
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    usable = FD_SETSIZE if hard == resource.RLIM_INFINITY else min(hard, FD_SETSIZE)
    was = soft
    if soft != usable:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (usable, hard))
            soft = usable
        except (ValueError, OSError) as exc:
            log.warning("process.file_limit_unchanged", soft=soft, hard=hard, error=str(exc))
    log.info(
        "process.file_limit",
        soft=soft,
        hard=-1 if hard == resource.RLIM_INFINITY else hard,
        was=was,
        why="the event loop waits in select(), on descriptors below 1024",
    )
    return soft, hard


def connection_budget() -> int:
    """How many connections the servers may hold in all without running out of files."""
    try:
        import resource
    except ImportError:  # pragma: no cover - not POSIX
        return FD_SETSIZE - FD_HEADROOM
    soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    usable = FD_SETSIZE if soft == resource.RLIM_INFINITY else min(soft, FD_SETSIZE)
    return max(0, usable - FD_HEADROOM)


class RepeatedErrors:
    """An event loop exception handler that logs each kind of error once per window."""

    def __init__(self, loop: asyncio.AbstractEventLoop, window_s: float = REPEAT_WINDOW_S) -> None:
        self.loop = loop
        self.window_s = window_s
        self._repeats: dict[tuple[str, str], int] = {}  # kind → repeats in its window

    def install(self) -> None:
        """Become the loop's exception handler."""
        self.loop.set_exception_handler(self)

    def __call__(self, loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
        """Log the first of a kind at once; count the rest until the window ends."""
        exception = context.get("exception")
        message = str(context.get("message", "unhandled exception in the event loop"))
        kind = (message, type(exception).__name__ if exception is not None else "")
        if kind in self._repeats:
            self._repeats[kind] += 1
            return
        self._repeats[kind] = 0
        self.loop.call_later(self.window_s, self._window_ended, kind)
        log.error(
            "loop.error",
            message=message,
            error=repr(exception) if exception is not None else None,
            exc_info=(type(exception), exception, exception.__traceback__)
            if isinstance(exception, BaseException)
            else None,
            repeats_logged_once_per_s=self.window_s,
        )

    def _window_ended(self, kind: tuple[str, str]) -> None:
        count = self._repeats.pop(kind, 0)
        if count:
            log.error(
                "loop.error_repeated",
                message=kind[0],
                error_type=kind[1] or None,
                count=count,
                over_s=self.window_s,
            )
