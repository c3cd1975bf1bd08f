"""Counters a line keeps about itself, cheap enough to update on every transaction."""

from __future__ import annotations

from bisect import bisect_left
from dataclasses import dataclass, field
from typing import Any, Final

# Seconds. Transaction latency spans 1 ms (115200 baud, process telegram) to a timeout.
LATENCY_BOUNDS: Final = (0.002, 0.005, 0.01, 0.02, 0.03, 0.05, 0.075, 0.1, 0.2, 0.5, 1.0)
# Seconds. The master's own turnaround beyond the protocol's pause.
TURNAROUND_BOUNDS: Final = (0.00005, 0.0001, 0.0002, 0.0005, 0.001, 0.002, 0.005, 0.01)
# Seconds. How late a line's timer fired (the end of a pause, a reply's deadline): the event
# loop's wake-up granularity is 1 ms; a stall (a long collection, a busy loop) shows as more.
LATENESS_BOUNDS: Final = (0.0001, 0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.5, 1.0)


class Histogram:
    """Fixed-bucket histogram (Prometheus style): bounded memory whatever the uptime."""

    __slots__ = ("bounds", "count", "counts", "sum")

    def __init__(self, bounds: tuple[float, ...]) -> None:
        self.bounds = bounds
        self.counts = [0] * (len(bounds) + 1)  # the last bucket is +Inf
        self.count = 0
        self.sum = 0.0

    def observe(self, value: float) -> None:
        """Count one observation."""
        self.counts[bisect_left(self.bounds, value)] += 1
        self.count += 1
        self.sum += value

    def to_json(self) -> dict[str, Any]:
        """Cumulative buckets, count and sum."""
        running, buckets = 0, []
        for bound, n in zip((*self.bounds, float("inf")), self.counts, strict=True):
            running += n
            buckets.append({"le": bound, "count": running})
        return {"buckets": buckets, "count": self.count, "sum": self.sum}


@dataclass(slots=True)
class DriveStats:
    """Per-drive counters."""

    requests: int = 0
    replies: int = 0
    timeouts: int = 0
    refused: int = 0
    last_latency_s: float | None = None
    first_request_at: float | None = None  # the master's first telegram to the drive


@dataclass(slots=True)
class LineStats:
    """Per-line counters and distributions."""

    requests: int = 0
    replies: int = 0
    timeouts: int = 0
    retries: int = 0
    broadcasts: int = 0
    checksum_errors: int = 0
    malformed: int = 0  # checked frames whose content did not decode
    unexpected: int = 0  # replies from another address or of the wrong kind
    noise_bytes: int = 0  # bytes skipped by the framer, checksum failures included
    late_bytes: int = 0  # discarded before a request: late replies, noise between exchanges
    reopens: int = 0
    crashes: int = 0  # unexpected exceptions that took the line down (logged as bus.crashed)
    observer_errors: int = 0  # exceptions an observer raised, kept away from the line
    down_reason: str | None = None  # why the line is down; None while it is up
    line_silent: bool = False  # every drive that answered fell silent together (a line fault)
    busy_s: float = 0.0  # time with a transaction in progress
    up_since: float | None = None
    latency: Histogram = field(default_factory=lambda: Histogram(LATENCY_BOUNDS))
    turnaround: Histogram = field(default_factory=lambda: Histogram(TURNAROUND_BOUNDS))
    wakeup_lateness: Histogram = field(default_factory=lambda: Histogram(LATENESS_BOUNDS))
    drives: dict[str, DriveStats] = field(default_factory=dict)

    def utilisation(self, now: float) -> float:
        """Share of time since the line came up that transactions took."""
        if self.up_since is None or now <= self.up_since:
            return 0.0
        return min(1.0, self.busy_s / (now - self.up_since))

    def to_json(self, now: float) -> dict[str, Any]:
        """Everything, as JSON-ready values."""
        return {
            "requests": self.requests,
            "replies": self.replies,
            "timeouts": self.timeouts,
            "retries": self.retries,
            "broadcasts": self.broadcasts,
            "checksum_errors": self.checksum_errors,
            "malformed": self.malformed,
            "unexpected": self.unexpected,
            "noise_bytes": self.noise_bytes,
            "late_bytes": self.late_bytes,
            "reopens": self.reopens,
            "crashes": self.crashes,
            "observer_errors": self.observer_errors,
            "down_reason": self.down_reason,
            "line_silent": self.line_silent,
            "utilisation": self.utilisation(now),
            "latency_s": self.latency.to_json(),
            "turnaround_s": self.turnaround.to_json(),
            "wakeup_lateness_s": self.wakeup_lateness.to_json(),
            "drives": {
                name: {
                    "requests": d.requests,
                    "replies": d.replies,
                    "timeouts": d.timeouts,
                    "refused": d.refused,
                    "last_latency_s": d.last_latency_s,
                }
                for name, d in self.drives.items()
            },
        }
