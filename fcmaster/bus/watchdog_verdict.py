"""The verdict on a drive's watchdog, and how it is said (DESIGN.md "Drive state").

Pure: a :class:`~fcmaster.protocol.watchdog.WatchdogSetting` read from the drive, the
line's worst-case poll round and what the daemon's start cost the drive (the restart gap)
make the :class:`Verdict`; :func:`say` logs it with the consequence and the fix in words.
The audit that reads the settings is :mod:`fcmaster.bus.watchdog`.

* ``ok`` — the drive stops (ramp or trip) once it hears nothing for longer than a round,
  and a gateway restart does not trip it: its timeout covers the restart gap
  (``restart_gap_s``: from the daemon's start until its first telegram to the drive, which
  the drive answered then or, powered off meanwhile, later) and a round after it (the first
  telegram of an adopted drive marks its control word not valid; the valid one follows
  within a round);
* ``off`` — it keeps running if the gateway dies (watchdog off, or an action such as
  FC's freeze output that leaves the motor turning);
* ``too_short`` — the timeout is shorter than a round, so normal polling trips it
  (Mitsubishi Pr.122 = 0 counts so: it trips as soon as the link commands), or shorter than
  the restart gap and a round, so a gateway restart trips it;
* ``unknown`` — the reads failed, or the setting's effect cannot be told (FC's set-up
  switch).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any, Final

from fcmaster.bus.plan import DrivePlan
from fcmaster.protocol.watchdog import WatchdogFacts, WatchdogSetting

# A timeout worth suggesting leaves room for retries, commands and probes between two
# polls of a drive: this many worst-case rounds, and never under a second.
SUGGESTED_ROUNDS: Final = 4
SUGGESTED_MIN_S: Final = 1.0


class Verdict(enum.StrEnum):
    """What a drive's watchdog does for a dead gateway (DESIGN.md "Drive state")."""

    OK = "ok"
    OFF = "off"
    TOO_SHORT = "too_short"
    UNKNOWN = "unknown"


@dataclass(slots=True, frozen=True)
class WatchdogReport:
    """A drive's watchdog as last read, and the verdict on it.

    ``restart_gap_s`` is what the daemon's start cost the drive (None: not measured); it is
    context for the verdict, not part of what the drive reported, so it does not take part
    in comparisons.
    """

    timeout_s: float | None
    action: str
    verdict: Verdict
    restart_gap_s: float | None = field(default=None, compare=False)

    def to_json(self) -> dict[str, Any]:
        """``{"timeout_s", "action", "verdict"}``, and ``restart_gap_s`` once measured."""
        out: dict[str, Any] = {
            "timeout_s": self.timeout_s,
            "action": self.action,
            "verdict": self.verdict.value,
        }
        if self.restart_gap_s is not None:
            out["restart_gap_s"] = self.restart_gap_s
        return out


def judge(setting: WatchdogSetting, round_s: float, restart_gap_s: float = 0.0) -> Verdict:
    """The verdict on ``setting`` for a line whose worst-case poll round is ``round_s``.

    ``restart_gap_s``: how long the daemon's start took to reach the drive; a timeout that
    does not cover it and a round after it (the first valid control word) trips the drive at
    every gateway restart.
    """
    if setting.stops is False or setting.timeout_s is None:
        return Verdict.OFF
    if setting.stops is None:
        return Verdict.UNKNOWN
    if setting.timeout_s < restart_gap_s + round_s:
        return Verdict.TOO_SHORT
    return Verdict.OK


def suggested_timeout_s(round_s: float) -> float:
    """A timeout to advise for a line whose worst-case poll round is ``round_s`` (0.1 s steps)."""
    return max(SUGGESTED_MIN_S, math.ceil(round_s * SUGGESTED_ROUNDS * 10 - 1e-9) / 10)


def say(
    log: Any,
    drive: DrivePlan,
    facts: WatchdogFacts,
    report: WatchdogReport,
    round_s: float,
    *,
    again: bool,
) -> None:
    """Log ``report``: ``off`` and ``too_short`` as warnings with the fix, unless ``again``.

    ``again``: the drive had this very warning before (a drive that comes and goes): said
    once, not at every return.
    """
    gap, verdict, timeout_s = report.restart_gap_s, report.verdict, report.timeout_s
    # with room for a restart like this one: twice its gap
    suggested = max(suggested_timeout_s(round_s), math.ceil((gap or 0.0) * 20) / 10)
    fix = facts.advice(suggested)
    if drive.watchdog is None:
        fix += f", or configure the drive with watchdog: {{timeout_s: {suggested:g}}}"
    fields: dict[str, Any] = {
        "drive": drive.name,
        "address": drive.address,
        "timeout_s": timeout_s,
        "action": report.action,
        "poll_round_s": round(round_s, 4),
        "restart_gap_s": None if gap is None else round(gap, 3),
    }
    if again:
        log.info("drive.watchdog_unchanged", **fields, verdict=verdict.value)
    elif verdict is Verdict.OFF:
        consequence = "the motor keeps running if the gateway dies"
        log.warning("drive.watchdog_off", **fields, consequence=consequence, fix=fix)
    elif verdict is Verdict.TOO_SHORT:
        restart = timeout_s is not None and timeout_s >= round_s
        consequence = (
            "a gateway restart trips the drive" if restart else "normal polling can trip the drive"
        )
        log.warning("drive.watchdog_too_short", **fields, consequence=consequence, fix=fix)
    elif verdict is Verdict.UNKNOWN:
        reason = f"what {report.action!r} does cannot be told from the parameters"
        log.info("drive.watchdog_unknown", **fields, reason=reason)
    else:
        log.info("drive.watchdog_checked", **fields, verdict=verdict.value)
