"""The control-intent algebra: what a command makes of a drive's commanded state.

A ``control: bus`` drive carries its :class:`~fcmaster.protocol.drive.ControlIntent` in
every exchange. These rules say what a command turns it into, what is adopted from a drive
found running, what is kept when the drive is lost or restarts (a stop, never a motion), and
what a probe may carry. All pure functions of the slot and the command.
"""

from __future__ import annotations

import dataclasses

from fcmaster.bus.commands import Action, Command
from fcmaster.bus.steps import DriveSlot, Pending
from fcmaster.protocol.codec import ParameterKey, Reply
from fcmaster.protocol.drive import ControlIntent, Motion, hz_to_pct

STOPPING = (Motion.STOP, Motion.COAST, Motion.QUICK_STOP)
REFERENCE_LIMIT_PCT = 199.99  # the most a reference can say (FC: 0x7FFF); adoption stays below
FALLING_HZ = 0.005  # an output lower than the one read before by more than this is falling
# Actions that change only part of the commanded state, so the rest must be known first
# (so does a start that keeps the present reference).
RELATIVE_ACTIONS = frozenset((Action.FORWARD, Action.REVERSE, Action.SET_REFERENCE, Action.RESET))


def needs_learning(slot: DriveSlot | None, pending: Pending) -> bool:
    """Whether the drive's state must be polled before ``pending`` can say its intent."""
    command = pending.command
    return (
        pending.intent is None
        and slot is not None
        and slot.intent is None
        and (
            command.action in RELATIVE_ACTIONS
            or (command.action is Action.START and command.reference_pct is None)
        )
    )


def learn(slot: DriveSlot, reply: Reply) -> None:
    """Keep what the drive is doing, for adoption.

    Protocols that read status and output in separate transactions (Mitsubishi, ENC, some
    Modbus profiles) tell it over several replies. The direction is the status's, or where
    the status has none, a signed output's (a reading's magnitude alone never says it).
    """
    status = reply.status
    if status is not None:
        slot.running = status.running
        slot.at_reference = status.at_reference
        slot.local = not status.accepts_bus_control
        if status.reverse is not None:
            slot.reverse = status.reverse
    output = reply.output_frequency_hz
    if output is not None:
        before = slot.output_hz
        slot.output_falling = None if before is None else abs(output) < before - FALLING_HZ
        slot.output_hz = abs(output)
        if output and reply.output_signed and (status is None or status.reverse is None):
            slot.reverse = output < 0  # the status does not say; a signed reading does


def _unlearn(slot: DriveSlot) -> None:
    """Drop what the drive was reported doing, so it is learned anew before adoption."""
    slot.running = slot.output_hz = slot.at_reference = slot.executed = None
    slot.output_falling = None
    slot.executed_asked = slot.executed_known = False


def forget(slot: DriveSlot) -> None:
    """What the drive was doing is no longer known: keep a stop, drop a motion."""
    _unlearn(slot)
    if slot.intent is not None and slot.intent.motion not in STOPPING:
        slot.intent = None


def unknown(slot: DriveSlot) -> None:
    """A command may or may not have been applied: command nothing until adopted again.

    Neither the previous intent (it would undo what the drive may be doing: a pulse) nor
    the timed-out one (it may never have been meant to hold) is repeated; the drive's next
    good status is adopted, as at start-up.
    """
    slot.intent = None
    _unlearn(slot)


def restarted(slot: DriveSlot, until: float) -> None:
    """The drive restarts and hears nothing until ``until``; its output is off."""
    slot.deaf_until = until
    _unlearn(slot)
    if slot.intent is not None:
        slot.intent = dataclasses.replace(slot.intent, motion=Motion.STOP, reset=False)


def current(slot: DriveSlot) -> ControlIntent:
    """What the drive is commanded now (a stop while nothing is)."""
    return slot.intent if slot.intent is not None else ControlIntent(Motion.STOP)


def without_reset(intent: ControlIntent) -> ControlIntent:
    """``intent`` after its reset pulse: a reset is sent once, not kept."""
    return dataclasses.replace(intent, reset=False) if intent.reset else intent


def stopping_only(intent: ControlIntent | None) -> ControlIntent | None:
    """A probe keeps commanding a stop but never a motion, so a returning drive is safe."""
    return intent if intent is not None and intent.motion in STOPPING else None


def apply(intent: ControlIntent, command: Command) -> ControlIntent:
    """The intent ``command`` makes of ``intent``."""
    action = command.action
    reference = intent.reference_pct if command.reference_pct is None else command.reference_pct
    match action:
        case Action.START:
            return ControlIntent(Motion.RUN, intent.reverse, reference)
        case Action.STOP:
            return ControlIntent(Motion.STOP, intent.reverse, reference)
        case Action.COAST:
            return ControlIntent(Motion.COAST, intent.reverse, reference)
        case Action.QUICK_STOP:
            return ControlIntent(Motion.QUICK_STOP, intent.reverse, reference)
        case Action.JOG:
            return ControlIntent(Motion.JOG, intent.reverse, reference)
        case Action.FORWARD:
            return ControlIntent(intent.motion, False, reference)
        case Action.REVERSE:
            return ControlIntent(intent.motion, True, reference)
        case Action.SET_REFERENCE:
            return ControlIntent(intent.motion, intent.reverse, reference)
        case Action.RESET:
            return ControlIntent(intent.motion, intent.reverse, reference, reset=True)
    raise AssertionError(f"not a control action: {action}")  # pragma: no cover


def adopted(slot: DriveSlot) -> ControlIntent | None:
    """The intent that keeps a drive doing what it does now; None while that is not known.

    A running drive is adopted only once its output is known too, so it is never commanded
    to a reference it is not running at. One found off its reference while what it
    executes was asked (:mod:`~fcmaster.bus.adoption`) waits for the answer: ramping down
    after a stop it keeps being told that stop, so a restart never starts it again.
    """
    if slot.running is False:
        return ControlIntent(Motion.STOP)
    if slot.running is None or slot.output_hz is None:
        return None
    if slot.executed_asked and slot.at_reference is False and not slot.local:
        if not slot.executed_known:
            return None
        if slot.executed is not None:
            return ControlIntent(slot.executed, slot.reverse)
    pct = min(hz_to_pct(slot.output_hz, slot.plan.nominal_frequency_hz), REFERENCE_LIMIT_PCT)
    return ControlIntent(Motion.RUN, slot.reverse, pct)


def learning_read(slot: DriveSlot, pending: Pending) -> ParameterKey | None:
    """What the next state-learning poll reads besides the status (None: status only)."""
    if slot.executed_asked and not slot.executed_known and slot.urgent_reads:
        return slot.urgent_reads[0]  # what it executes, asked by adoption: before the rest
    reads = [key for key in slot.sequence if key is not None]
    if not pending.learned or not reads:
        return None
    return reads[(pending.learned - 1) % len(reads)]
