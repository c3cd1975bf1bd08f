"""Communication timeout detection, F2.16 (protocols/enc.md §1).

F2.16 is 0.0-1000.0 s in 0.1 s steps; 0.0 (the factory setting) switches it off. The
manual does not say what the drive does when the time runs out; the likely result is a
trip with fault 16, RS-485 communication fault, and that is what is assumed here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from fcmaster.protocol.watchdog import WatchdogFacts, WatchdogSetting, check_timeout

__all__ = ["WATCHDOG"]

TIMEOUT: Final = "F2.16"


def _decode(values: Sequence[float]) -> WatchdogSetting:
    (timeout_s,) = values
    if timeout_s == 0:
        return WatchdogSetting(timeout_s=None, action="off", stops=False)
    return WatchdogSetting(timeout_s=float(timeout_s), action="trip", stops=True)


def _encode(timeout_s: float, action: str) -> tuple[tuple[str, float], ...]:
    check_timeout(WATCHDOG, timeout_s, action)
    return ((TIMEOUT, timeout_s),)


def _advice(timeout_s: float) -> str:
    return f"set F2.16 Communication timeout detection to {timeout_s:g} s or more (0.0 is off)"


WATCHDOG: Final = WatchdogFacts(
    parameters=(TIMEOUT,),
    decode=_decode,
    actions=("trip",),  # fault 16 (assumed: the manual does not say)
    timeout_range_s=(0.1, 1000.0),
    encode=_encode,
    advice=_advice,
)
