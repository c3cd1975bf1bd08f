"""What goes wrong on a simulated line: the fault plan, per line and per drive.

Every rate is a probability per event, drawn from the line's seeded ``random.Random`` so
a run can be repeated exactly:

* ``drop``: a reply is lost on the wire (the drive did act on the request).
* ``corrupt``: one bit of one byte of a reply flips, so its check character fails.
* ``noise``: after a request, a burst of 1 to ``noise_bytes`` random bytes reaches the master
  while the drives are still inside their response delay.
* ``late``: a reply starts ``late_s`` later than the drive's response delay (usually past
  the master's deadline, so it collides with or trails into the next transaction).
* ``silent``: instead of answering, the drive goes deaf and mute for ``silent_s`` (a
  power dip or a loose connector), then comes back.
* ``silent_periods``: fixed ``(start, end)`` windows, in seconds after the line was built,
  during which the drive (or, in a line's plan, every drive) neither hears nor answers.
* ``echo``: the master hears its own bytes back, as on a two-wire adapter without echo
  suppression. Only a line's plan can ask for it.

A garbled request needs no fault of its own: a drive never answers one, so the master sees
exactly what ``drop`` gives it.

The ``--faults`` text form is ``drop=0.05,corrupt=0.01,late=0.01,late_s=0.3,echo,
silent_at=10-15,seed=7``: comma-separated ``key=value`` items, a bare ``echo``, and
``silent_at`` as often as needed.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Final

from fcmaster.errors import UsageError
from fcmaster.suggest import did_you_mean

_RATES: Final = ("drop", "corrupt", "noise", "late", "silent")
_DURATIONS: Final = ("late_s", "silent_s")


@dataclass(slots=True, frozen=True, kw_only=True)
class FaultPlan:
    """Fault rates and windows for a line or for one drive (see the module docstring)."""

    drop: float = 0.0
    corrupt: float = 0.0
    noise: float = 0.0
    noise_bytes: int = 6
    late: float = 0.0
    late_s: float = 0.2
    silent: float = 0.0
    silent_s: float = 2.0
    silent_periods: tuple[tuple[float, float], ...] = ()
    echo: bool = False
    seed: int | None = None  # for whoever builds the line's random.Random

    def __post_init__(self) -> None:
        for name in _RATES:
            rate = getattr(self, name)
            if not 0.0 <= rate <= 1.0:
                raise UsageError(f"fault rate {name}={rate} is outside 0…1")
        for name in _DURATIONS:
            if not (getattr(self, name) >= 0.0 and math.isfinite(getattr(self, name))):
                raise UsageError(f"fault duration {name} must be a finite number ≥ 0")
        if self.noise_bytes < 1:
            raise UsageError("noise_bytes must be at least 1")
        for start, end in self.silent_periods:
            if not 0.0 <= start < end:
                raise UsageError(f"silent period {start}-{end} must have 0 ≤ start < end")

    @property
    def is_quiet(self) -> bool:
        """Whether the plan injects nothing at all."""
        return self == FaultPlan(seed=self.seed)

    def is_silent_period(self, elapsed_s: float) -> bool:
        """Whether ``elapsed_s`` (seconds since the line was built) is in a silent window."""
        return any(start <= elapsed_s < end for start, end in self.silent_periods)

    def merged(self, other: FaultPlan) -> FaultPlan:
        """The plan a drive's replies follow: this (line) plan together with ``other`` (drive).

        Rates combine as independent chances (1 − (1 − a)(1 − b)); durations come from
        ``other`` where it uses that fault; silent windows add up. Echo and noise stay the
        line's, since they are properties of the wire, not of a drive.
        """
        combined = {}
        for name in ("drop", "corrupt", "late", "silent"):
            a, b = getattr(self, name), getattr(other, name)
            combined[name] = a + b - a * b  # exact when either is 0
        return dataclasses.replace(
            self,
            **combined,
            late_s=other.late_s if other.late else self.late_s,
            silent_s=other.silent_s if other.silent else self.silent_s,
            silent_periods=self.silent_periods + other.silent_periods,
        )


_KNOWN: Final = (*_RATES, *_DURATIONS, "noise_bytes", "silent_at", "echo", "seed")


def parse_faults(text: str) -> FaultPlan:
    """The plan written as ``drop=0.05,corrupt=0.01,echo,silent_at=10-15`` (UsageError if not)."""
    values: dict[str, Any] = {}  # keys checked against the fields below
    periods: list[tuple[float, float]] = []
    for raw_item in text.split(","):
        item = raw_item.strip()
        if not item:
            continue
        key, sep, value = (part.strip() for part in item.partition("="))
        if key == "echo":
            values["echo"] = not sep or _flag(value)
        elif key not in _KNOWN:
            raise UsageError(f"unknown fault {key!r}{did_you_mean(key, _KNOWN)}; known: "
                             f"{', '.join(_KNOWN)}")  # fmt: skip
        elif not sep:
            raise UsageError(f"fault {item!r} needs a value, like {item}=0.01")
        elif key in _RATES or key in _DURATIONS:
            values[key] = _number(key, value)
        elif key == "noise_bytes" or key == "seed":
            values[key] = _integer(key, value)
        elif key == "silent_at":
            start, dash, end = value.partition("-")
            if not dash:
                raise UsageError(f"silent_at={value}: write the window as START-END seconds")
            periods.append((_number(key, start), _number(key, end)))
    return FaultPlan(silent_periods=tuple(periods), **values)


def _number(key: str, text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise UsageError(f"fault {key}={text!r} is not a number") from None


def _integer(key: str, text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise UsageError(f"fault {key}={text!r} is not a whole number") from None


def _flag(text: str) -> bool:
    if text.lower() in ("1", "true", "yes", "on"):
        return True
    if text.lower() in ("0", "false", "no", "off"):
        return False
    raise UsageError(f"echo={text!r}: write echo, echo=1 or echo=0")
