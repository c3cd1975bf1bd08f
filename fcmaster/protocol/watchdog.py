"""A drive's own communication watchdog: the shape of each vendor's facts about it.

Every drive family can supervise the link itself: when the master falls silent for longer
than a set time, the drive acts (stops, trips, or on some settings runs on). Each vendor
package has a ``watchdog`` module with one :class:`WatchdogFacts`: which parameters hold the
setting, how their values turn into a :class:`WatchdogSetting`, and which values to write
for a wanted timeout and action. Judging a setting against a line's poll round is the bus's
business (:mod:`fcmaster.bus.watchdog`); nothing here knows about time or I/O.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from fcmaster.errors import UsageError

__all__ = ["WatchdogFacts", "WatchdogSetting", "check_timeout"]


@dataclass(slots=True, frozen=True, kw_only=True)
class WatchdogSetting:
    """What a drive's watchdog parameters say, in words every vendor shares."""

    timeout_s: float | None  # None: no time is supervised (the watchdog is off)
    action: str  # what the drive does when the time runs out, in words ("stop", "off", …)
    # True: the motor stops (ramp or trip); False: it keeps turning (off, freeze, max speed);
    # None: cannot be told from the parameters (FC: switching to another set-up)
    stops: bool | None


@dataclass(slots=True, frozen=True, kw_only=True)
class WatchdogFacts:
    """One vendor's watchdog parameters and what their values mean."""

    # The parameters to read, as the manual writes them; ``decode`` gets their values in
    # this order, each in the parameter's unit.
    parameters: tuple[str, ...]
    decode: Callable[[Sequence[float]], WatchdogSetting]
    # The actions a config may ask for (each stops the motor); the first is the default.
    actions: tuple[str, ...]
    timeout_range_s: tuple[float, float]  # what the timeout parameter accepts (0.1 s steps)
    # (timeout_s, action) → the writes that set it, in order; UsageError for a bad value.
    encode: Callable[[float, str], tuple[tuple[str, float], ...]]
    # What to set to switch the watchdog on with at least ``timeout_s``, in words.
    advice: Callable[[float], str]


def check_timeout(facts: WatchdogFacts, timeout_s: float, action: str) -> None:
    """UsageError unless ``timeout_s`` and ``action`` can be written as they are.

    Never rounded or clamped: a timeout between two 0.1 s steps or outside the parameter's
    range is refused, like a reference beyond a drive's limits.
    """
    low, high = facts.timeout_range_s
    if not low <= timeout_s <= high:
        raise UsageError(f"{timeout_s:g} s is outside {low:g}-{high:g} s")
    if abs(round(timeout_s * 10) - timeout_s * 10) > 1e-6:
        raise UsageError(f"{timeout_s:g} s is not a whole number of 0.1 s steps")
    if action not in facts.actions:
        raise UsageError(f"action {action!r} is not one of {', '.join(facts.actions)}")
