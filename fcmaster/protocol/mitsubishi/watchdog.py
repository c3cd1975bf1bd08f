"""The communication check time interval: Pr.122 or Pr.336, by the port the link is wired to.

Every family has the PU connector, supervised by Pr.122 (its trip: E.PUE). The models with
RS-485 terminals as well (A700/F700, A800/F800 and the 800 series' RS-485 terminal models)
run the computer link on those too, and supervise them with Pr.336 (its trip: E.SER). Each
port has its own check, armed by the first request it hears, so a drive wired to its
terminals is protected by Pr.336 alone: its Pr.122 sees no traffic and never trips. The
line key ``drive_port`` (``pu`` | ``terminals``) says which one a line's drives are wired
to; :func:`watchdog_for` gives the facts of that port (protocols/mitsubishi.md §1.1).

Both parameters take the same values: 0.1-999.8 s, when no communication arrives for that
long the inverter trips; 9999: no check. 0 means different things by model: either the
port does not communicate at all, or it does but the inverter trips as soon as the link
commands it. A drive that answers us at 0 is of the second kind, so 0 is read as a timeout
of 0 s: shorter than any poll round (``too_short``), never protection.

The retry counts (Pr.121 / Pr.335, trips on reception errors) are not a silence watchdog
and are not read: they trip on noise, not on a dead master.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from fcmaster.protocol.watchdog import WatchdogFacts, WatchdogSetting, check_timeout

__all__ = ["DRIVE_PORTS", "WATCHDOG", "check_parameter", "watchdog_for"]

NO_CHECK: Final = 9999
# The port a line is wired to → its check time interval parameter and how the manual names it.
_CHECKS: Final = {
    "pu": ("Pr.122", "PU communication check time interval"),
    "terminals": ("Pr.336", "RS-485 communication check time interval"),
}
DRIVE_PORTS: Final = tuple(_CHECKS)  # the values of the line key, the default first


def check_parameter(drive_port: str) -> str:
    """The parameter that supervises ``drive_port`` (``"Pr.122"``, ``"Pr.336"``)."""
    return _CHECKS[drive_port][0]


def _decode(values: Sequence[float]) -> WatchdogSetting:
    (interval,) = values
    if interval == NO_CHECK:
        return WatchdogSetting(timeout_s=None, action="off", stops=False)
    return WatchdogSetting(timeout_s=float(interval), action="trip", stops=True)


def _facts(drive_port: str) -> WatchdogFacts:
    parameter, name = _CHECKS[drive_port]
    facts: WatchdogFacts

    def encode(timeout_s: float, action: str) -> tuple[tuple[str, float], ...]:
        check_timeout(facts, timeout_s, action)
        return ((parameter, timeout_s),)

    def advice(timeout_s: float) -> str:
        return (
            f"set {parameter} {name} to {timeout_s:g} s or more "
            "(not 9999, which switches the check off, nor 0)"
        )

    facts = WatchdogFacts(
        parameters=(parameter,),
        decode=_decode,
        actions=("trip",),  # the only thing the check does
        timeout_range_s=(0.1, 999.8),
        encode=encode,
        advice=advice,
    )
    return facts


_FACTS: Final = {port: _facts(port) for port in DRIVE_PORTS}
WATCHDOG: Final = _FACTS["pu"]  # the PU connector's: every model has one


def watchdog_for(drive_port: str) -> WatchdogFacts:
    """The watchdog facts of a line wired to ``drive_port`` (``pu`` | ``terminals``)."""
    return _FACTS[drive_port]
