"""A drive's ``watchdog`` key: the communication watchdog fcmaster writes at adoption.

Checked here against the protocol's watchdog facts (its actions, its timeout range and step)
and against the line's worst-case poll round, each problem at its own key.
"""

from __future__ import annotations

from fcmaster.bus.plan import LinePlan, WatchdogPlan
from fcmaster.bus.poll_round import poll_round_s
from fcmaster.config_sections import StrictModel as _Model
from fcmaster.errors import UsageError
from fcmaster.protocol.registry import spec_for
from fcmaster.protocol.watchdog import check_timeout

__all__ = ["WatchdogModel", "watchdog_plan", "watchdogs_outlast_round"]


class WatchdogModel(_Model):
    """A drive's ``watchdog``: the communication watchdog fcmaster gives it at adoption."""

    timeout_s: float
    action: str | None = None  # None: the protocol's first action (FC: stop; others: trip)


def watchdog_plan(
    protocol: str,
    wanted: WatchdogModel | None,
    control: str,
    at: str,
    problems: list[tuple[str, str]],
    profile: object = None,
) -> WatchdogPlan | None:
    """A drive's ``watchdog`` as a plan; its problems, each at its key, into ``problems``.

    ``profile``: the drive's profile, where its protocol has them (modbus-rtu), whose
    watchdog registers and actions are the drive's.
    """
    if wanted is None:
        return None
    # The protocol's facts for any line: where they depend on a line key (Mitsubishi's
    # drive_port: Pr.122 or Pr.336), only the parameter differs, not the actions or range.
    spec = spec_for(protocol)
    facts = spec.drive_watchdog(None, profile)
    action = wanted.action or facts.actions[0]
    found = len(problems)
    if control != "bus":
        problems.append(
            (f"{at}.watchdog", "fcmaster writes the watchdog only of a `control: bus` drive")
        )
    if action not in facts.actions:
        problems.append(
            (
                f"{at}.watchdog.action",
                f"{action!r} is not an action of {protocol} drives' watchdog "
                f"(one of: {', '.join(facts.actions)})",
            )
        )
    else:
        try:
            check_timeout(facts, wanted.timeout_s, action)
        except UsageError as exc:
            problems.append((f"{at}.watchdog.timeout_s", str(exc)))
        # Where the drive's own facts come from its profile (modbus-rtu), one without
        # watchdog registers has nowhere to write it: refused here, not by the audit at run
        # time. A drive whose profile is missing has that problem named already.
        if len(problems) == found and (profile is not None or spec.watchdog_of_profile is None):
            try:
                facts.encode(wanted.timeout_s, action)
            except UsageError as exc:
                problems.append((f"{at}.watchdog", str(exc)))
    return WatchdogPlan(wanted.timeout_s, action) if len(problems) == found else None


def watchdogs_outlast_round(line: LinePlan, where: str, problems: list[tuple[str, str]]) -> None:
    """A configured watchdog shorter than the line's worst-case poll round would trip."""
    if not any(drive.watchdog for drive in line.drives):
        return
    try:
        round_s = poll_round_s(line)[0]
    except UsageError:  # a monitor list the drive loop has already reported
        return
    for d, drive in enumerate(line.drives):
        if drive.watchdog is not None and drive.watchdog.timeout_s < round_s:
            problems.append(
                (
                    f"{where}.drives[{d}].watchdog.timeout_s",
                    f"{drive.watchdog.timeout_s:g} s is shorter than the line's worst-case "
                    f"poll round of {round_s * 1000:.1f} ms: normal polling would trip the drive",
                )
            )
