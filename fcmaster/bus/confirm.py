"""Confirmation: whether a drive's status shows what a motion command asked for.

An acknowledged telegram only says that the drive heard it. A drive in local (hand)
operation, a tripped one, or one whose run enable is missing hears a start and does not
turn. So start and jog are ``done`` only once the status shows the drive running, and stop,
coast and quick stop only once it shows it not running, within the drive's confirmation
deadline; otherwise they end ``unconfirmed`` with what the drive reports instead.
References, directions, resets and parameter writes are ``done`` on the acknowledgement of
the telegram that carries them.

The deadline is the drive's ``confirm_s`` when configured. Otherwise a stop gets the
drive's own deceleration time (read once each time it comes online, where the protocol can
poll it: FC 3-42, ENC F0.09; scaled by the output above nominal) plus a grace, and never
less than a few seconds; everything else gets those few seconds, since a drive shows
itself running as soon as its output rises.

All pure functions of the slot, the command and the time it is now.
"""

from __future__ import annotations

from fcmaster.bus.commands import Action, CommandResult, Outcome
from fcmaster.bus.steps import DriveSlot, Pending, result_of
from fcmaster.errors import UsageError
from fcmaster.protocol.codec import DriveCodec, ParameterKey, Reply
from fcmaster.protocol.drive import hz_to_pct
from fcmaster.protocol.registry import spec_for

CONFIRM_DEFAULT_S = 5.0  # a few seconds: a start shows at once, most stops take less
RAMP_GRACE_S = 2.0  # beyond the deceleration time: start delays, load, the poll round
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


def ramp_keys(codec: DriveCodec) -> tuple[ParameterKey, ParameterKey] | None:
    """The drive's acceleration and deceleration parameters, where a poll can read them."""
    # In seconds, from 0 to the drive's nominal or maximum frequency; a protocol whose ramp
    # times a poll cannot read has none, and its drives use the default or confirm_s.
    names = spec_for(codec.protocol).ramp_parameters
    if names is None:
        return None
    try:
        return codec.parameter(names[0]), codec.parameter(names[1])
    except UsageError:  # pragma: no cover - the table names parameters the codecs know
        return None


def note_ramp(slot: DriveSlot, keys: tuple[ParameterKey, ParameterKey], reply: Reply) -> None:
    """Keep a ramp time that ``reply`` read."""
    value = reply.value
    if value is None or isinstance(value.value, str):
        return
    if value.parameter == keys[0]:
        slot.ramp_up_s = float(value.value)
    elif value.parameter == keys[1]:
        slot.ramp_down_s = float(value.value)


def confirm_time(slot: DriveSlot, pending: Pending) -> float:
    """How long the status may take to show ``pending``'s result."""
    if pending.command.action in (Action.STOP, Action.QUICK_STOP):
        return stop_time(slot)
    return CONFIRM_DEFAULT_S if slot.plan.confirm_s is None else slot.plan.confirm_s


def stop_time(slot: DriveSlot) -> float:
    """How long a stop of ``slot`` may take to show: configured, or by its ramp, once read."""
    if slot.plan.confirm_s is not None:
        return slot.plan.confirm_s
    if slot.ramp_down_s is None:
        return CONFIRM_DEFAULT_S
    scale = max(1.0, _pct(slot) / 100.0)
    return max(CONFIRM_DEFAULT_S, slot.ramp_down_s * scale + RAMP_GRACE_S)


def stop_known(slot: DriveSlot) -> bool:
    """Whether :func:`stop_time` follows the drive (configured, or its ramp read)."""
    return slot.plan.confirm_s is not None or slot.ramp_down_s is not None


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
        return result_of(Outcome.UNCONFIRMED, what_instead(slot, wanted, pending.confirm_s))
    return None


def alarm_text(slot: DriveSlot) -> str:
    """The drive's active alarms in words, as its alarm words last said."""
    texts = [text for source in slot.alarms.values() for text in source]
    return "; ".join(texts) if texts else "an alarm (its word shows none active)"


def what_instead(slot: DriveSlot, wanted: bool, confirm_s: float) -> str:
    """What the drive shows after the deadline instead of the result asked for."""
    if slot.running is None:
        return f"no status from the drive within {confirm_s:g} s"
    word = "" if slot.status_word is None else f" (status word 0x{slot.status_word:04X})"
    if not wanted:
        output = "" if slot.output_hz is None else f" at {_pct(slot):.1f} % of nominal"
        return f"still running{output} {confirm_s:g} s after the command{word}"
    if slot.fault:
        return f"not running after {confirm_s:g} s: the drive reports a fault{word}"
    return f"not running after {confirm_s:g} s: the drive reports ready but stopped{word}"


def _pct(slot: DriveSlot) -> float:
    """The drive's last reported output in % of its nominal frequency (0 when not known)."""
    return hz_to_pct(slot.output_hz or 0.0, slot.plan.nominal_frequency_hz)
