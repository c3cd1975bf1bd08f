"""Admission: whether a command may go on the line at all, decided when it is submitted.

A command that cannot be carried out (no such drive, a monitor-only drive, a reference
beyond the configured limits or beyond what the wire carries, a broadcast that cannot say
the same thing to every drive, a parameter that does not exist) is refused here with a
reason, before anything is queued: it never reaches the wire, and nothing is clamped.
"""

from __future__ import annotations

from collections.abc import Sequence

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.bus.intents import apply, current
from fcmaster.bus.plan import DrivePlan
from fcmaster.bus.steps import DriveSlot, result_of
from fcmaster.errors import UsageError
from fcmaster.protocol.codec import DriveCodec, Exchange
from fcmaster.protocol.drive import ControlIntent, Motion, pct_to_hz

# What one telegram to every drive may carry: whole states, never a change of part of one.
BROADCASTS = frozenset((Action.START, Action.STOP, Action.COAST, Action.QUICK_STOP))


def refusal(
    codec: DriveCodec,
    line: str,
    slots: Sequence[DriveSlot],
    name: str | None,
    slot: DriveSlot | None,
    command: Command,
) -> CommandResult | None:
    """Why ``command`` for drive ``name`` (None: every drive) is refused; None: it is not."""
    action = command.action
    if name is not None and slot is None:
        return result_of(Outcome.INVALID, f"no drive called {name!r} on {line}")
    targets = [slot] if slot is not None else slots
    if slot is None:
        reason = broadcast_refusal(codec, command)
        if reason:
            return result_of(Outcome.INVALID, reason)
    if action is Action.WRITE and slot is not None and not slot.plan.control:
        return result_of(
            Outcome.NOT_ALLOWED,
            f"{slot.name} is monitor-only: writing its parameters needs control: bus",
        )
    if action.is_control:
        monitor_only = [s.name for s in targets if not s.plan.control]
        if monitor_only:
            return result_of(
                Outcome.NOT_ALLOWED,
                f"{', '.join(monitor_only)} is monitor-only (not configured control: bus)",
            )
    if command.reference_pct is not None:
        for target in targets:
            reason = beyond_limits(target.plan, command.reference_pct)
            if reason:
                return result_of(Outcome.NOT_ALLOWED, reason)
        if command.reference_pct < 0:  # every surface refuses it first; a caller may not
            return result_of(
                Outcome.INVALID,
                f"reference {command.reference_pct:g} % is not a magnitude (≥ 0): "
                "change the direction with forward or reverse",
            )
        try:  # NaN, or beyond what the wire carries: it would fail when sent instead
            # As a run: codecs that send the frequency only with a run (ENC) check it then.
            intent = ControlIntent(Motion.RUN, reference_pct=command.reference_pct)
            codec.control(0 if slot is None else slot.address, intent)
        except UsageError as exc:
            return result_of(Outcome.INVALID, str(exc))
    if action.is_control:
        for target in targets:
            reason = beyond_profile(codec, target, command)
            if reason:
                return result_of(Outcome.INVALID, reason)
    if action in (Action.READ, Action.WRITE) and slot is not None:
        try:
            build_access(codec, slot, command)
        except UsageError as exc:
            return result_of(Outcome.INVALID, str(exc))
    return None


def beyond_profile(codec: DriveCodec, slot: DriveSlot, command: Command) -> str:
    """Why ``slot``'s drive cannot be told what ``command`` makes of it ("" if it can).

    A Modbus drive's profile may lack a command (coast, jog) or a way to run in reverse; a
    command that needs one is refused here, never found missing as it is sent. A direction
    is checked as a run in it, since a stopped drive told to reverse runs so at its start.
    """
    intent = apply(current(slot), command)
    try:
        codec.control(slot.address, intent)
        if intent.reverse:
            codec.control(slot.address, ControlIntent(Motion.RUN, True, intent.reference_pct))
    except UsageError as exc:
        return f"{slot.name}: {exc}"
    return ""


def broadcast_refusal(codec: DriveCodec, command: Command) -> str:
    """Why ``command`` cannot go to every drive at once ("" when it can)."""
    if not codec.can_broadcast:
        return f"{codec.protocol} has no broadcast; command the drives one by one"
    if command.action not in BROADCASTS:
        allowed = ", ".join(sorted(a.value for a in BROADCASTS))
        return f"only {allowed} can be broadcast (one telegram sets every drive alike)"
    if command.action is Action.START and command.reference_pct is None:
        return "a broadcast start needs a reference: every drive gets the same one"
    return ""


def build_access(codec: DriveCodec, slot: DriveSlot, command: Command) -> tuple[Exchange, ...]:
    """The exchanges of a parameter read or write (UsageError: it cannot be built)."""
    parameter = codec.parameter(command.parameter or "")
    if command.action is Action.READ:
        return codec.read(slot.address, parameter, command.index, slot.intent)
    if command.value is None:
        raise UsageError("write needs a value")
    return codec.write(
        slot.address,
        parameter,
        command.index,
        command.value,
        slot.intent,
        persist=command.persist,
    )


def beyond_limits(drive: DrivePlan, reference_pct: float) -> str:
    """Why ``reference_pct`` is outside the drive's configured frequencies ("" if it is not)."""
    frequency = pct_to_hz(reference_pct, drive.nominal_frequency_hz)
    if abs(frequency) > drive.max_frequency_hz + 1e-9:
        return (
            f"{frequency:g} Hz is beyond {drive.name}'s configured limit of "
            f"{drive.max_frequency_hz:g} Hz"
        )
    if frequency and abs(frequency) < drive.min_frequency_hz - 1e-9:
        return (
            f"{frequency:g} Hz is below {drive.name}'s configured minimum of "
            f"{drive.min_frequency_hz:g} Hz"
        )
    return ""
