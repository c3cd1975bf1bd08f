"""Taking over a ``control: bus`` drive: command exactly what it is doing.

A drive found stopped is told to stay stopped, one running at its reference to keep running
at its present output. A drive found running *off* its reference is ramping: towards a new
speed, or down after a stop it was given before the master (re)started, still reporting
itself running until its output reaches 0 Hz. Its status alone cannot tell these apart.

Where a poll can read what the drive executes (FC: 16-00, the control word it obeys) that
is read first, and a drive executing a stop is adopted with that stop: a gateway killed
during an operator's stop never commands the motor back to speed; one executing motion is
adopted running at its present output.

Where nothing tells (Mitsubishi, ENC), a drive running off its reference (Mitsubishi: SU
off; ENC never says) is adopted only once two reads of its output show it is not falling,
and one whose output falls is not adopted until it stands (a stop) or holds its speed
(running there): until then a command that
changes only part of its state (a reference, a direction) cannot be built on it and is not
sent, so it cannot start a drive that was stopping. On these protocols the idle poll never
commands, so an adopted intent is only the master's note of what the drive does: it follows
the drive (a drive adopted running that then stands is noted stopped) until a command
replaces it, so a reference sent later never starts a drive that stopped meanwhile.

Pure functions of the slot and the reply, like :mod:`~fcmaster.bus.intents`.
"""

from __future__ import annotations

from collections.abc import Callable

from fcmaster.bus.intents import adopted
from fcmaster.bus.steps import DriveSlot
from fcmaster.errors import UsageError
from fcmaster.protocol.codec import DriveCodec, ParameterKey, Reply
from fcmaster.protocol.drive import ControlIntent, Motion
from fcmaster.protocol.registry import spec_for

# The parameter a poll reads for what a drive executes, and its value → the stop it is.
Executed = tuple[ParameterKey, Callable[[int], Motion | None]]


class Adoption:
    """How one line's drives are taken over (see the module docstring)."""

    def __init__(self, codec: DriveCodec) -> None:
        """The rules for drives spoken to through ``codec``."""
        self.executed = executed_control(codec)
        address = next(iter(codec.addresses))
        # Where polls never command, an adopted intent follows the drive (see above).
        self.follows = not codec.poll(address, ControlIntent(), None).carries_control

    def heard(self, slot: DriveSlot, reply: Reply, asked: ParameterKey | None) -> None:
        """A reply (to a read of ``asked``) from the bus-controlled ``slot``: adopt it where due."""
        if slot.intent is None or (self.follows and slot.intent is slot.adopted):
            take_over(slot, reply, self.executed, asked)


def executed_control(codec: DriveCodec) -> Executed | None:
    """Where a drive of ``codec``'s protocol tells what it executes; None: nowhere a poll reads."""
    facts = spec_for(codec.protocol).executed_control
    if facts is None:
        return None
    try:
        return codec.parameter(facts.parameter), facts.stopping
    except UsageError:  # pragma: no cover - the spec names parameters its codec knows
        return None


def take_over(
    slot: DriveSlot, reply: Reply, executed: Executed | None, asked: ParameterKey | None = None
) -> None:
    """Adopt ``slot`` from ``reply`` (to a read of ``asked``) once its state is known enough."""
    if executed is not None:
        key, stopping = executed
        value = reply.value
        if value is not None and value.parameter == key and isinstance(value.raw, int):
            slot.executed, slot.executed_known = stopping(value.raw), True
        elif asked == key and reply.error is not None:
            # A drive that has no such parameter tells nothing: adopted by its status.
            slot.executed, slot.executed_known = None, True
        elif (
            slot.running
            and slot.at_reference is False
            and not slot.local  # in local operation the bus word is not what it executes
            and not slot.executed_known
            and key not in slot.urgent_reads
        ):
            slot.executed_asked = True
            slot.urgent_reads.appendleft(key)  # the next poll asks it (again, if one was lost)
    intent = adopted(slot)
    if (
        executed is None
        and intent is not None
        and intent.motion is Motion.RUN
        and (slot.output_falling or (slot.output_falling is None and not slot.at_reference))
    ):
        # Ramping down (stopping, or slowing to a new speed), or off its reference and not
        # known yet whether it is: one output read says nothing of where it is going.
        intent = None
    slot.intent = slot.adopted = intent


def not_adopted(slot: DriveSlot) -> str:
    """Why ``slot``'s state is not known well enough to build a command on it, in words."""
    if slot.running and slot.output_falling:
        return "running with its output falling (stopping, or slowing to a new speed)"
    if slot.running and slot.output_falling is None and slot.output_hz is not None:
        return "running, and its output read only once: whether it is falling is not known"
    return "running, but no output reported"
