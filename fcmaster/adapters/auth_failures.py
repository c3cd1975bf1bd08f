"""Wrong tokens per client address: counted, throttled, and logged in aggregate.

An address may present :data:`FAILURES_PER_WINDOW` wrong or malformed tokens in
:data:`FAILURE_WINDOW_S`; beyond that its requests are answered 429 without a token being
looked at, right or wrong, until the window ends, so guessing goes at ten tokens a minute.
The log gets one line when an address first fails in a window (``http.auth_failed``), one
when it is throttled (``http.auth_throttled``), and one with the count of what it sent
while throttled (``http.auth_throttled_requests``) — never a line per wrong token.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

import structlog

from fcmaster.adapters.auth import AuthError

log = structlog.get_logger("fcmaster.adapters.http")

FAILURES_PER_WINDOW: Final = 10  # wrong tokens an address may send in a window
FAILURE_WINDOW_S: Final = 60.0
MAX_ADDRESSES: Final = 4096  # addresses remembered (the least recent are forgotten)


@dataclass(slots=True)
class _Failures:
    since: float  # the window's start
    count: int = 0  # failures in the window
    throttled: int = 0  # requests refused unlooked-at in the window


class FailedAuthentications:
    """Wrong tokens per client address: counted, throttled, logged in aggregate."""

    def __init__(
        self,
        now: Callable[[], float],
        *,
        per_window: int = FAILURES_PER_WINDOW,
        window_s: float = FAILURE_WINDOW_S,
    ) -> None:
        self.now = now
        self.per_window = per_window
        self.window_s = window_s
        self._hosts: OrderedDict[str, _Failures] = OrderedDict()
        self.failed = self.throttled = 0  # since start, for the status

    def _window(self, host: str) -> _Failures | None:
        entry = self._hosts.get(host)
        now = self.now()
        if entry is not None and now - entry.since >= self.window_s:
            if entry.throttled:
                log.warning(
                    "http.auth_throttled_requests", client=host, count=entry.throttled,
                    over_s=round(now - entry.since, 1),
                )  # fmt: skip
            del self._hosts[host]
            entry = None
        return entry

    def check(self, host: str) -> None:
        """AuthError 429 while ``host`` has used up its failures in this window."""
        entry = self._window(host)
        if entry is not None and entry.count >= self.per_window:
            entry.throttled += 1
            self.throttled += 1
            left = entry.since + self.window_s - self.now()
            error = AuthError(
                429,
                f"too many failed authentications from this address: try again in {left:.0f} s",
                retry_after_s=left,
            )
            error.counted = True
            raise error

    def fail(self, host: str, error: AuthError) -> None:
        """``host`` presented a token that let it nowhere."""
        self.failed += 1
        error.counted = True
        entry = self._window(host)
        if entry is None:
            entry = self._hosts[host] = _Failures(since=self.now())
            if len(self._hosts) > MAX_ADDRESSES:
                self._hosts.popitem(last=False)
            log.warning("http.auth_failed", client=host, reason=error.reason)
        self._hosts.move_to_end(host)
        entry.count += 1
        if entry.count == self.per_window:
            log.warning(
                "http.auth_throttled", client=host, failures=entry.count,
                window_s=self.window_s,
            )  # fmt: skip
