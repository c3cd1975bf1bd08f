"""The daemon's own health: how long the garbage collector stops the process.

A full collection walks every object the process holds; with many long-lived ones (an
OPC UA server's address space, a large fleet's states) it can stall the event loop, and
with it every line's timers, for hundreds of milliseconds. Two things keep that visible
and short: :func:`watch_gc` times each collection (``gc.callbacks``) into a histogram that
``/metrics`` shows as ``fcmaster_gc_pause_seconds``, and :func:`freeze_start_up` moves
everything the daemon built at start-up (config, codecs, adapters, the fleet's first
states) into the permanent generation (``gc.freeze``), so later full collections skip it.

The collector is one per process, so the watch is too: installed once, kept until the
process ends.
"""

from __future__ import annotations

import gc
import time
from typing import Any, Final

from fcmaster.bus.stats import Histogram

__all__ = ["freeze_start_up", "gc_pauses", "thaw", "watch_gc"]

# Seconds. A young-generation pass takes microseconds; a full one over a big heap, more
# than a poll round.
GC_PAUSE_BOUNDS: Final = (0.0001, 0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.5, 1.0)


class _GcWatch:
    """Times each collection from its start callback to its stop callback."""

    __slots__ = ("_started", "histogram")

    def __init__(self) -> None:
        self.histogram = Histogram(GC_PAUSE_BOUNDS)
        self._started = 0.0

    def __call__(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._started = time.perf_counter()
        else:
            self.histogram.observe(time.perf_counter() - self._started)


_watch: _GcWatch | None = None


def watch_gc() -> None:
    """Time every collection from now on (once per process; calling again does nothing)."""
    global _watch
    if _watch is None:
        _watch = _GcWatch()
        gc.callbacks.append(_watch)


def gc_pauses() -> dict[str, Any] | None:
    """The collections' pauses so far (``Histogram.to_json``); None if not watched."""
    return None if _watch is None else _watch.histogram.to_json()


def freeze_start_up() -> int:
    """Collect what start-up left over, then freeze the rest; how many objects were frozen."""
    gc.collect()
    gc.freeze()
    return gc.get_freeze_count()


def thaw() -> None:
    """Undo :func:`freeze_start_up` (the service ended; the process may serve again)."""
    gc.unfreeze()
