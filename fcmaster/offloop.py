"""Long pure-Python work kept off the loop: a config validated, the HTTP app built, a journal.

The loop that serves the lines must wake within a fraction of a millisecond of its timers
and of a reply's arrival. Work of tens of milliseconds run on it delays every line by that
much; run on a worker thread it still takes the interpreter lock, in slices of the switch
interval (5 ms by default), and each wake-up of the loop waits for the slice to end:
measured, about 10 ms late per wake-up while a config was validated beside a 2 ms timer.
While such work runs, the switch interval is made short, and the loop waits a fraction of a
millisecond for its turn instead (0.6-3 ms late, measured the same way).
"""

from __future__ import annotations

import asyncio
import contextlib
import sys
import threading
from collections.abc import Callable, Iterator
from typing import TypeVar

T = TypeVar("T")
SWITCH_S = 0.0005  # the interpreter's switch interval while such work runs

_lock = threading.Lock()
_running = 0
_saved = 0.0


async def run_off_loop(work: Callable[[], T]) -> T:
    """``work()`` on a worker thread, with the loop kept responsive meanwhile."""
    return await asyncio.to_thread(_briskly, work)


def _briskly(work: Callable[[], T]) -> T:
    with brisk():
        return work()


@contextlib.contextmanager
def brisk() -> Iterator[None]:
    """On a worker thread: the switch interval short while inside (nested and concurrent)."""
    global _running, _saved
    with _lock:
        if not _running:  # the first of several at once saves, the last restores
            _saved = sys.getswitchinterval()
            sys.setswitchinterval(SWITCH_S)
        _running += 1
    try:
        yield
    finally:
        with _lock:
            _running -= 1
            if not _running:
                sys.setswitchinterval(_saved)
