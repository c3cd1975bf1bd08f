"""The watchdog facts of Modbus RTU drives: each drive's come from its profile.

A Modbus drive's communication watchdog lives in registers its family chooses (ABB
58.14-58.16, SINAMICS V20 P2014, Altivar TTO/SLL, …), which its drive profile names
(:class:`~.profile.WatchdogProfile`). The line-wide facts here read nothing and say so:
the verdict stays "unknown" until the audit reads each drive's own registers.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.modbus_rtu.keys import register_key
from fcmaster.protocol.modbus_rtu.profile import DriveProfile
from fcmaster.protocol.watchdog import WatchdogFacts, WatchdogSetting, check_timeout


def _decode(values: Sequence[float]) -> WatchdogSetting:
    return WatchdogSetting(timeout_s=None, action="per drive profile", stops=None)


def _encode(timeout_s: float, action: str) -> tuple[tuple[str, float], ...]:
    # Only a drive whose profile has no watchdog registers gets these facts (profile_facts).
    raise UsageError(
        "the drive's profile names no watchdog registers (no watchdog: timeout in it), and a "
        "Modbus drive's watchdog is set through them"
    )


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


def profile_facts(profile: object) -> WatchdogFacts | None:
    """The watchdog facts of a drive that follows ``profile`` (None: not a drive profile).

    Its registers are read as parameters (``hr5815``), in the profile's scaling, and judged
    by the profile's rules; the actions a config may ask for are those that stop the motor.
    """
    if not isinstance(profile, DriveProfile) or profile.watchdog.timeout is None:
        return None
    watchdog, timeout = profile.watchdog, profile.watchdog.timeout
    registers = {"timeout": timeout, "action": watchdog.action, "enable": watchdog.enable}
    names = {k: register_key(r).name for k, r in registers.items() if r is not None}
    stopping = {text: value for value, (text, stops) in watchdog.actions.items() if stops}
    what = profile.title or profile.name

    def encode(timeout_s: float, action: str) -> tuple[tuple[str, float], ...]:
        check_timeout(facts, timeout_s, action)
        writes: list[tuple[str, float]] = [(names["timeout"], timeout_s)]
        if "action" in names and action in stopping:  # else the file says no value's meaning
            writes.append((names["action"], stopping[action]))
        if "enable" in names:
            writes.append((names["enable"], 1))
        return tuple(writes)

    def advice(timeout_s: float) -> str:
        return (
            f"set the communication loss time of {what} (register {names['timeout']}) to "
            f"{timeout_s:g} s or more, with an action that stops the motor"
        )

    largest = timeout.scale * ((1 << (16 * timeout.words)) - 1)
    facts = WatchdogFacts(
        parameters=tuple(names.values()),
        decode=watchdog.setting,
        actions=tuple(stopping) or (watchdog.fixed_action,),
        timeout_range_s=(0.1, min(6000.0, largest)),
        encode=encode,
        advice=advice,
    )
    return facts
