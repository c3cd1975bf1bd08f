"""``fcmaster`` with every line's wake-up lateness kept sample by sample, for the benchmarks.

Run: ``python benchmarks/lateness_tap.py OUT.json run --config FILE`` — the command line of
``fcmaster`` (after OUT), in a process that also keeps each observation of a line's
``wakeup_lateness`` histogram (``fcmaster_bus_wakeup_lateness_seconds``) with its time
(``time.monotonic()``, the same clock in every process of the machine) and writes them to
OUT as it exits: ``{"lines": {HISTOGRAM: [[t, seconds], ...]}}``, one histogram per line
(named by the order they were first observed: ``0``, ``1``, …).

The histogram's buckets step 0.1/0.5/1/2/5 ms, too coarse to tell a 0.1 ms change; the raw
samples let a benchmark compute the p99 of any window. Nothing in ``fcmaster/`` changes: the
histogram's ``observe`` is wrapped here, and costs every observation the same in every window.
"""

from __future__ import annotations

import atexit
import json
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def load(path: Path) -> dict[str, list[tuple[float, float]]]:
    """Each line's samples as OUT holds them: ``(monotonic time, lateness s)``."""
    lines: dict[str, list[list[float]]] = json.loads(path.read_text())["lines"]
    return {name: [(t, s) for t, s in samples] for name, samples in lines.items()}


def p99(samples: list[tuple[float, float]], start: float, end: float) -> float | None:
    """The 99th percentile of the samples taken in ``[start, end)`` (None: there were none)."""
    return quantile(taken(samples, start, end), 0.99)


def taken(samples: list[tuple[float, float]], start: float, end: float) -> list[float]:
    """The samples taken in ``[start, end)``, without their times."""
    return [s for t, s in samples if start <= t < end]


def quantile(values: list[float], q: float) -> float | None:
    """The ``q`` quantile of ``values`` (None: there are none)."""
    ordered = sorted(values)
    if not ordered:
        return None
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def main(out: Path, argv: list[str]) -> int:
    """Run ``fcmaster ARGV`` keeping the lateness samples; write them to ``out`` at exit."""
    sys.path.insert(0, str(ROOT))
    from fcmaster.bus import stats
    from fcmaster.cli import main as fcmaster

    kept: dict[int, list[tuple[float, float]]] = {}
    observe = stats.Histogram.observe
    clock = time.monotonic

    def observed(self: stats.Histogram, value: float) -> None:
        observe(self, value)
        if self.bounds is stats.LATENESS_BOUNDS:  # a line's wake-up lateness, no other
            kept.setdefault(id(self), []).append((clock(), value))

    stats.Histogram.observe = observed  # type: ignore[method-assign]

    def write() -> None:
        lines: dict[str, Any] = {str(n): s for n, s in enumerate(kept.values())}
        out.write_text(json.dumps({"lines": lines}))

    atexit.register(write)
    return fcmaster(argv)


if __name__ == "__main__":
    raise SystemExit(main(Path(sys.argv[1]), sys.argv[2:]))
