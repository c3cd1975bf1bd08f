"""Recent history of every drive and line, so a chart opened later still has its past.

Theory of operation
-------------------
The fleet state records a drive's sample each time it *publishes* the drive (a visible
change, or the heartbeat), never per poll, so recording costs nothing on a steady fleet.
A line's sample comes with its statistics (every few seconds): counters become rates
between two samples.

Memory is bounded whatever happens: each ring keeps ``window_s`` of samples, at most one
per ``spacing_s`` on average — a new sample that comes less than ``spacing_s`` after the
one before the last replaces the last, so a drive that changes on every poll still keeps
two samples a spacing and the last one is always the latest. Times are wall-clock seconds
(the times the readings were taken), as charts show them.

Readers get columns (``t`` and one list per series), the shape chart libraries take.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

WINDOW_S: Final = 15 * 60.0
SPACING_S: Final = 2.0
EVENTS_KEPT: Final = 30  # a drive's recent discrete events (alarms, availability, commands)
# LineStats counters shown as rates, and the error counters summed into "errors"
_LINE_RATES: Final = ("requests", "replies", "timeouts", "retries")
_LINE_ERRORS: Final = ("checksum_errors", "malformed", "unexpected")


@dataclass(slots=True, frozen=True)
class Series:
    """What one drive series is: its key, the manual's name and its unit."""

    key: str
    name: str
    unit: str


@dataclass(slots=True, frozen=True)
class _Sample:
    t: float
    values: Mapping[str, float | None]


class _Ring:
    def __init__(self, window_s: float, spacing_s: float) -> None:
        self.window_s = window_s
        self.spacing_s = spacing_s
        # two samples a spacing at the most, and one more
        self.samples: deque[_Sample] = deque(maxlen=int(2 * window_s / spacing_s) + 1)

    def add(self, sample: _Sample) -> None:
        samples = self.samples
        if len(samples) >= 2 and sample.t - samples[-2].t < self.spacing_s:
            samples[-1] = sample
        else:
            samples.append(sample)
        while samples and samples[0].t < sample.t - self.window_s:
            samples.popleft()

    def columns(self, keys: list[str]) -> tuple[list[float], dict[str, list[float | None]]]:
        t = [s.t for s in self.samples]
        return t, {key: [s.values.get(key) for s in self.samples] for key in keys}


class History:
    """Bounded rings of recent samples, one per drive and one per line."""

    def __init__(self, *, window_s: float = WINDOW_S, spacing_s: float = SPACING_S) -> None:
        self.window_s = window_s
        self._spacing_s = spacing_s
        self._drives: dict[str, _Ring] = {}
        self._series: dict[str, dict[str, Series]] = {}
        self._lines: dict[str, _Ring] = {}
        self._counters: dict[str, tuple[float, Mapping[str, Any]]] = {}
        self._events: dict[str, deque[tuple[float, object]]] = {}

    def _ring(self, rings: dict[str, _Ring], key: str) -> _Ring:
        ring = rings.get(key)
        if ring is None:
            ring = rings[key] = _Ring(self.window_s, self._spacing_s)
        return ring

    def record_drive(
        self, key: str, t: float, values: Mapping[str, float | None], series: dict[str, Series]
    ) -> None:
        """One sample of drive ``key`` (``bus/name``) at wall time ``t``.

        ``values`` maps a series key to its value (None: not known then, a gap);
        ``series`` describes every key, so a reader can label its charts (the caller's
        mapping is kept, not copied: it may only grow).
        """
        self._series[key] = series
        self._ring(self._drives, key).add(_Sample(t, values))

    def drive(self, key: str) -> dict[str, Any]:
        """``{"window_s", "t", "series": [{"key", "name", "unit", "data"}]}`` of a drive."""
        ring = self._drives.get(key)
        series = list(self._series.get(key, {}).values())
        if ring is None:
            return {"window_s": self.window_s, "t": [], "series": []}
        t, data = ring.columns([s.key for s in series])
        return {
            "window_s": self.window_s,
            "t": t,
            "series": [
                {"key": s.key, "name": s.name, "unit": s.unit, "data": data[s.key]} for s in series
            ],
        }

    def record_event(self, key: str, t: float, event: object) -> None:
        """A discrete event of drive ``key`` at wall time ``t`` (the newest are kept)."""
        kept = self._events.get(key)
        if kept is None:
            kept = self._events[key] = deque(maxlen=EVENTS_KEPT)
        kept.append((t, event))

    def events(self, key: str) -> list[tuple[float, object]]:
        """Drive ``key``'s recent events, oldest first, with their wall times."""
        return list(self._events.get(key, ()))

    def record_line(self, bus: str, t: float, stats: Mapping[str, Any]) -> None:
        """A line's statistics at wall time ``t``: rates since the previous sample."""
        previous = self._counters.get(bus)
        self._counters[bus] = (t, stats)
        if previous is None or t <= previous[0]:
            return
        then, old = previous
        span = t - then

        def rate(keys: tuple[str, ...]) -> float | None:
            if not all(isinstance(stats.get(k), int | float) for k in keys):
                return None
            now_total = float(sum(stats[k] for k in keys))
            old_total = float(sum(old.get(k, 0) for k in keys))
            return max(0.0, (now_total - old_total) / span)  # a restarted line starts over

        values: dict[str, float | None] = {f"{k}_per_s": rate((k,)) for k in _LINE_RATES}
        values["errors_per_s"] = rate(_LINE_ERRORS)
        utilisation = stats.get("utilisation")
        values["utilisation"] = utilisation if isinstance(utilisation, int | float) else None
        self._ring(self._lines, bus).add(_Sample(t, values))

    def line(self, bus: str) -> dict[str, Any]:
        """``{"window_s", "t", "series": {name: data}}`` of a line's rates."""
        keys = [f"{k}_per_s" for k in _LINE_RATES] + ["errors_per_s", "utilisation"]
        ring = self._lines.get(bus)
        if ring is None:
            return {"window_s": self.window_s, "t": [], "series": {k: [] for k in keys}}
        t, data = ring.columns(keys)
        return {"window_s": self.window_s, "t": t, "series": data}
