"""The line-wide watchdog facts of Modbus RTU lines: each drive's are in its profile.

A Modbus drive's communication watchdog lives in registers its family chooses (ABB
58.14-58.16, SINAMICS V20 P2014, Altivar TTO/SLL, …), which its drive profile names
(:class:`~.profile.WatchdogProfile`). The line-wide facts here read nothing and say so:
the verdict stays "unknown" until the audit reads each drive's own registers.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.watchdog import WatchdogFacts, WatchdogSetting


def _decode(values: Sequence[float]) -> WatchdogSetting:
    return WatchdogSetting(timeout_s=None, action="per drive profile", stops=None)


def _encode(timeout_s: float, action: str) -> tuple[tuple[str, float], ...]:
    raise UsageError("a Modbus drive's watchdog is set through its profile's registers")


def _advice(timeout_s: float) -> str:
    return (
        f"set the drive's communication loss time to {timeout_s:g} s or more, with an "
        "action that stops the motor (its profile names the registers)"
    )


WATCHDOG: Final = WatchdogFacts(
    parameters=(),
    decode=_decode,
    actions=("trip",),
    timeout_range_s=(0.1, 6000.0),
    encode=_encode,
    advice=_advice,
)
