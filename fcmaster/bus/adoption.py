"""Taking over a ``control: bus`` drive: command exactly what it is doing.

A drive found stopped is told to stay stopped, one running at its reference to keep running
at its present output. A drive found running *off* its reference is ramping: towards a new
speed, or down after a stop it was given before the master (re)started, still reporting
itself running until its output reaches 0 Hz. Its status alone cannot tell these apart, so
where the protocol lets a poll read what the drive executes (FC: 16-00, the control word it
obeys) that is read first, and a drive executing a stop is adopted with that stop: a gateway
killed during an operator's stop never commands the motor back to speed. A drive executing
motion, or on a protocol with nothing to read, is adopted running at its present output.

Pure functions of the slot and the reply, like :mod:`~fcmaster.bus.intents`.
"""

from __future__ import annotations

from collections.abc import Callable

from fcmaster.bus.intents import adopted
from fcmaster.bus.steps import DriveSlot
from fcmaster.errors import UsageError
from fcmaster.protocol.codec import DriveCodec, ParameterKey, Reply
from fcmaster.protocol.drive import Motion
from fcmaster.protocol.registry import spec_for

# The parameter a poll reads for what a drive executes, and its value → the stop it is.
Executed = tuple[ParameterKey, Callable[[int], Motion | None]]


def executed_control(codec: DriveCodec) -> Executed | None:
    """Where a drive of ``codec``'s protocol tells what it executes; None: nowhere a poll reads."""
    facts = spec_for(codec.protocol).executed_control
    if facts is None:
        return None
    try:
        return codec.parameter(facts.parameter), facts.stopping
    except UsageError:  # pragma: no cover - the spec names parameters its codec knows
        return None


def take_over(slot: DriveSlot, reply: Reply, executed: Executed | None) -> None:
    """Adopt the not yet commanded ``slot`` from ``reply`` once its state is known enough."""
    if executed is not None:
        key, stopping = executed
        value = reply.value
        if value is not None and value.parameter == key and isinstance(value.raw, int):
            slot.executed, slot.executed_known = stopping(value.raw), True
        elif slot.running and slot.at_reference is False and not slot.executed_asked:
            slot.executed_asked = True
            slot.urgent_reads.appendleft(key)  # the next poll asks it, before anything else
    slot.intent = adopted(slot)
