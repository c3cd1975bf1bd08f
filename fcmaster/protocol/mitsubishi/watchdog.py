"""The communication check time interval, Pr.122 (protocols/mitsubishi.md §1.1).

Pr.122 supervises the PU connector, the port the computer link runs on (the RS-485
terminals of the models that have them use Pr.336 in the same way). 0.1-999.8 s: when no
communication arrives for that long, the inverter trips (E.PUE). 9999: no check. 0 means
different things by model: either the port does not communicate at all, or it does but
the inverter trips as soon as the link commands it. A drive that answers us at 0 is of the
second kind, so 0 is read as a timeout of 0 s: shorter than any poll round (``too_short``),
never protection.

Pr.121 (retries before a trip on reception errors) is not a silence watchdog and is not
read: it trips on noise, not on a dead master.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from fcmaster.protocol.watchdog import WatchdogFacts, WatchdogSetting, check_timeout

__all__ = ["WATCHDOG"]

CHECK_INTERVAL: Final = "Pr.122"
NO_CHECK: Final = 9999


def _decode(values: Sequence[float]) -> WatchdogSetting:
    (interval,) = values
    if interval == NO_CHECK:
        return WatchdogSetting(timeout_s=None, action="off", stops=False)
    return WatchdogSetting(timeout_s=float(interval), action="trip", stops=True)


def _encode(timeout_s: float, action: str) -> tuple[tuple[str, float], ...]:
    check_timeout(WATCHDOG, timeout_s, action)
    return ((CHECK_INTERVAL, timeout_s),)


def _advice(timeout_s: float) -> str:
    return (
        f"set Pr.122 PU communication check time interval to {timeout_s:g} s or more "
        "(not 9999, which switches the check off, nor 0)"
    )


WATCHDOG: Final = WatchdogFacts(
    parameters=(CHECK_INTERVAL,),
    decode=_decode,
    actions=("trip",),  # the only thing the check does
    timeout_range_s=(0.1, 999.8),
    encode=_encode,
    advice=_advice,
)
