"""The watchdog audit's reads and writes: the line's command path, within a share of it.

The audit's exchanges go through the line's ordinary command queue one at a time for the
whole line, each followed by a rest nine times as long as it took (``AUDIT_SHARE``), so the
audit takes at most a tenth of the line's time however many drives come online together.
A read or write that fails because the line went down, or because its drive went offline,
judges nothing (None): the drive's return audits it again.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Awaitable, Callable
from typing import Any, Final

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.bus.plan import DrivePlan, WatchdogPlan
from fcmaster.clock import Clock
from fcmaster.protocol.watchdog import WatchdogFacts

ACTOR: Final = "watchdog-audit"  # the audit line's actor for the reads and writes
AUDIT_SHARE: Final = 0.1  # the most of the line's time the audit's exchanges take
AUDIT_REST_MAX_S: Final = 10.0  # the longest rest after one exchange (one that timed out)

Execute = Callable[[str, Command], Awaitable[CommandResult]]


class AuditAccess:
    """Reads and writes a drive's watchdog parameters for the audit."""

    def __init__(self, clock: Clock, log: Any, offline: set[str]) -> None:
        self.execute: Execute | None = None  # the line's BusMaster, once it exists
        self._clock = clock
        self._log = log
        self._offline = offline  # drives that went offline since they last answered
        self._turn = asyncio.Lock()  # one audit exchange at a time on the line

    async def exchange(self, name: str, command: Command) -> CommandResult:
        """Carry out ``command``, then rest, keeping the audit to its share of the line."""
        execute = self.execute
        assert execute is not None
        async with self._turn:
            started = self._clock.now()
            result = await execute(name, command)
            spent = self._clock.now() - started
            rest = spent * (1.0 - AUDIT_SHARE) / AUDIT_SHARE
            await self._clock.sleep(min(rest, AUDIT_REST_MAX_S))
        return result

    async def read(
        self, drive: DrivePlan, facts: WatchdogFacts
    ) -> tuple[list[float] | None, str | None]:
        """The watchdog parameters' values; else None and why (None too: line gone)."""
        values: list[float] = []
        for parameter in facts.parameters:
            command = Command(action=Action.READ, parameter=parameter, actor=ACTOR, internal=True)
            result = await self.exchange(drive.name, command)
            if result.outcome is Outcome.CANCELLED or (
                not result.ok and drive.name in self._offline
            ):
                return None, None  # the line or the drive is gone: its return audits again
            value = result.value
            if result.outcome is not Outcome.DONE or value is None:
                return None, f"{parameter} could not be read ({result.outcome.value}: " + (
                    f"{result.reason})" if result.reason else "no value)"
                )
            if isinstance(value.value, str):
                return None, f"{parameter} read as text {value.value!r}, not a number"
            values.append(float(value.value))
        return values, None

    async def write(
        self, drive: DrivePlan, wanted: WatchdogPlan, writes: tuple[tuple[str, float], ...]
    ) -> Outcome | None:
        """Write the configured setting: DONE, or the first write's failure (None: line gone)."""
        for parameter, value in writes:
            command = Command(
                action=Action.WRITE, parameter=parameter, value=value, persist=True, actor=ACTOR
            )
            result = await self.exchange(drive.name, command)
            if result.outcome is Outcome.CANCELLED or (
                not result.ok and drive.name in self._offline
            ):
                return None
            if result.outcome is not Outcome.DONE:
                self._log.warning(
                    "drive.watchdog_write_failed",
                    drive=drive.name,
                    param=parameter,
                    value=value,
                    outcome=result.outcome.value,
                    reason=result.reason or None,
                    wanted_timeout_s=wanted.timeout_s,
                    wanted_action=wanted.action,
                    retry="once the drive is seen stopped"
                    if result.outcome is Outcome.REFUSED
                    else None,
                )
                return result.outcome
        self._log.info(
            "drive.watchdog_written",
            drive=drive.name,
            timeout_s=wanted.timeout_s,
            action=wanted.action,
        )
        return Outcome.DONE


def matches(
    facts: WatchdogFacts, values: list[float], writes: tuple[tuple[str, float], ...]
) -> bool:
    """Whether the values read already hold what ``writes`` would write."""
    read = dict(zip(facts.parameters, values, strict=True))
    return all(
        parameter in read and math.isclose(read[parameter], value, abs_tol=1e-6)
        for parameter, value in writes
    )
