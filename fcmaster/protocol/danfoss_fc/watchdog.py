"""The FC control-word timeout: 8-03 (time) and 8-04 (function), protocols/danfoss-fc.md §3, §11.

8-03 Control Word Timeout Time is a Uint32 in 0.1 s (conversion index -1), so a read gives
seconds. 8-04 Control Word Timeout Function is an option number (FC 102 list): [0] Off, the
factory setting; [1] Freeze output; [2] Stop; [3] Jogging; [4] Max. speed; [5] Stop and
trip; [7]-[10] select set-up 1-4; [20] N2 override release. Only Stop and Stop and trip
bring the motor to rest; freeze, jog and max. speed keep it turning, so for a gateway that
dies they are as good as Off. What a set-up switch does depends on that set-up, which a
read of 8-04 cannot tell.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from fcmaster.protocol.watchdog import WatchdogFacts, WatchdogSetting, check_timeout

__all__ = ["WATCHDOG"]

TIMEOUT_TIME: Final = "8-03"
TIMEOUT_FUNCTION: Final = "8-04"
# 8-04 option → (words, whether the motor stops)
_FUNCTIONS: Final[dict[int, tuple[str, bool | None]]] = {
    0: ("off", False),
    1: ("freeze output", False),
    2: ("stop", True),
    3: ("jogging", False),
    4: ("max. speed", False),
    5: ("stop and trip", True),
    7: ("select set-up 1", None),
    8: ("select set-up 2", None),
    9: ("select set-up 3", None),
    10: ("select set-up 4", None),
    20: ("N2 override release", None),
}
# What a config's action writes to 8-04.
_OPTIONS: Final = {"stop": 2, "trip": 5}


def _decode(values: Sequence[float]) -> WatchdogSetting:
    timeout_s, function = values
    option = int(function)
    words, stops = _FUNCTIONS.get(option, (f"option [{option}]", None))
    return WatchdogSetting(
        timeout_s=None if option == 0 else float(timeout_s), action=words, stops=stops
    )


def _encode(timeout_s: float, action: str) -> tuple[tuple[str, float], ...]:
    check_timeout(WATCHDOG, timeout_s, action)
    # The time first: the function then never acts on a timeout left over from before.
    return ((TIMEOUT_TIME, timeout_s), (TIMEOUT_FUNCTION, _OPTIONS[action]))


def _advice(timeout_s: float) -> str:
    return (
        f"set 8-04 Control Word Timeout Function to [2] Stop (or [5] Stop and trip) and "
        f"8-03 Control Word Timeout Time to {timeout_s:g} s or more"
    )


WATCHDOG: Final = WatchdogFacts(
    parameters=(TIMEOUT_TIME, TIMEOUT_FUNCTION),
    decode=_decode,
    actions=tuple(_OPTIONS),
    # 0.1 s is the LonWorks manual's lower end; FC 102's list starts at 1.0 s. A drive that
    # does not take the value refuses the write, and the read-back shows what it kept.
    timeout_range_s=(0.1, 18000.0),
    encode=_encode,
    advice=_advice,
)
