"""Confirmation: whether a drive's status shows what a motion command asked for.

An acknowledged telegram only says that the drive heard it. A drive in local (hand)
operation, a tripped one, or one whose run enable is missing hears a start and does not
turn. So start and jog are ``done`` only once the status shows the drive running, and stop,
coast and quick stop only once it shows it not running, within the drive's confirmation
deadline (``confirm_s``); otherwise they end ``unconfirmed`` with what the drive reports
instead. References, directions, resets and parameter writes are ``done`` on the
acknowledgement of the telegram that carries them.

All pure functions of the slot, the command and the time it is now.
"""

from __future__ import annotations

from fcmaster.bus.commands import Action, CommandResult, Outcome
from fcmaster.bus.steps import DriveSlot, Pending, result_of

CONFIRM_DEFAULT_S = 5.0  # a few seconds: most ramps to standstill and to a first speed
# The running state each confirmed action must show.
SHOWS_RUNNING = {
    Action.START: True,
    Action.JOG: True,
    Action.STOP: False,
    Action.COAST: False,
    Action.QUICK_STOP: False,
}
LOCAL = "the drive is in local operation and ignores bus commands (status word: no bus control)"


def needs_confirmation(pending: Pending) -> bool:
    """Whether ``pending`` is done only once the drive's status shows its result."""
    return pending.slot is not None and pending.command.action in SHOWS_RUNNING


def deadline(slot: DriveSlot, now: float) -> float:
    """When a command acknowledged at ``now`` must show its result by."""
    confirm_s = slot.plan.confirm_s
    return now + (CONFIRM_DEFAULT_S if confirm_s is None else confirm_s)


def verdict(slot: DriveSlot, pending: Pending, now: float) -> CommandResult | None:
    """How ``pending`` ends given what its drive reports now; None: not decided yet."""
    wanted = SHOWS_RUNNING[pending.command.action]
    if slot.running is wanted:
        return result_of(Outcome.DONE, "")
    if slot.local:
        return result_of(Outcome.UNCONFIRMED, LOCAL)
    if wanted and slot.fault and slot.alarms_read:
        return result_of(Outcome.UNCONFIRMED, f"the drive is tripped: {alarm_text(slot)}")
    if now >= pending.confirm_by:
        return result_of(Outcome.UNCONFIRMED, what_instead(slot, wanted))
    return None


def alarm_text(slot: DriveSlot) -> str:
    """The drive's active alarms in words, as its alarm words last said."""
    texts = [text for source in slot.alarms.values() for text in source]
    return "; ".join(texts) if texts else "an alarm (its word shows none active)"


def what_instead(slot: DriveSlot, wanted: bool) -> str:
    """What the drive shows after the deadline instead of the result asked for."""
    confirm_s = slot.plan.confirm_s or CONFIRM_DEFAULT_S
    if slot.running is None:
        return f"no status from the drive within {confirm_s:g} s"
    word = "" if slot.status_word is None else f" (status word 0x{slot.status_word:04X})"
    if not wanted:
        output = "" if slot.output_pct is None else f" at {slot.output_pct:.1f} % of nominal"
        return f"still running{output} {confirm_s:g} s after the command{word}"
    if slot.fault:
        return f"not running after {confirm_s:g} s: the drive reports a fault{word}"
    return f"not running after {confirm_s:g} s: the drive reports ready but stopped{word}"
