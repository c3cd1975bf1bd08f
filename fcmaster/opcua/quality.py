"""What each variable of a drive shows: its value, quality and source time (no asyncua).

The quality codes are the ones SCADA reads (OPC 10000-4 §7.11, 10000-8 §7.3):

- never read since the start → ``BadWaitingForInitialData`` with a null value (a Bad status
  carries no value; ``Bad_NotConnected`` would say "never configured", which is not so);
- the drive stopped answering, or its line is down → ``UncertainNoCommunicationLastUsableValue``
  with the last value read;
- otherwise ``Good``.

The source time is when the value was read from the drive (the output frequency and each
value keep their own, which may be older than the status beside them); ``Online`` is the
gateway's own judgement, known at every moment, so it is always Good and stamped now.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Final


class Quality(enum.StrEnum):
    """The status codes a value may carry (asyncua's StatusCodes names)."""

    GOOD = "Good"
    WAITING = "BadWaitingForInitialData"
    NO_COMMUNICATION = "UncertainNoCommunicationLastUsableValue"


@dataclass(slots=True, frozen=True)
class Reading:
    """One variable's value as a client reads it (``source_at``: wall seconds, or None)."""

    path: str  # under the drive: "Running", "Values/Motor Current"
    value: Any
    quality: Quality
    source_at: float | None


# variable → (key in the drive's compact entry, key of its reading time)
STATUS: Final = {
    "Running": "running",
    "Fault": "fault",
    "Warning": "warning",
    "AtReference": "at_reference",
    "Direction": "direction",
    "StatusWord": "status_word",
    "ReferencePercent": "ref",
    "Alarms": "alarms",
    "Warnings": "warnings",
    "WatchdogVerdict": "wd",
}


def quality(value: Any, read_at: float | None, *, answering: bool) -> Quality:
    """The quality of ``value`` read at ``read_at``, while the drive is ``answering`` or not."""
    if value is None or read_at is None:
        return Quality.WAITING
    return Quality.GOOD if answering else Quality.NO_COMMUNICATION


def readings(entry: Mapping[str, Any], *, line_up: bool) -> Iterator[Reading]:
    """Every variable of a drive's compact entry (see :mod:`.wire`)."""
    answering = bool(entry.get("online")) and line_up
    yield Reading("Online", answering, Quality.GOOD, None)
    at = entry.get("at")
    for path, key in STATUS.items():
        yield _reading(path, entry.get(key), at, answering)
    yield _reading("OutputFrequency", entry.get("f"), entry.get("f_at"), answering)
    for name, (value, read_at) in entry.get("values", {}).items():
        yield _reading(f"Values/{name}", value, read_at, answering)


def _reading(path: str, value: Any, read_at: float | None, answering: bool) -> Reading:
    kind = quality(value, read_at, answering=answering)
    return Reading(path, None if kind is Quality.WAITING else value, kind, read_at)
