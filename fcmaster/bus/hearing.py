"""What a reply says about its drive: liveness, adoption, ramps, trips, alarms to read.

Every valid reply, a poll's or a command's, is news of its drive: it is alive (the
:class:`~fcmaster.bus.rotation.Rotation` keeps it in the round), its state is learned (the
intent algebra's :func:`~fcmaster.bus.intents.learn`), a ``control: bus`` drive not yet
taken over is adopted from it (:mod:`~fcmaster.bus.adoption`) and has its ramp times read
once (so a start's confirmation deadline follows the drive's ramp), a command waiting for
its result is judged by it (:mod:`~fcmaster.bus.unconfirmed`), and a change of the fault
or warning bits puts the reads of the drive's alarm and warning words first in its queue,
so the texts follow the bits within a poll or two.
"""

from __future__ import annotations

from fcmaster.bus.adoption import Adoption
from fcmaster.bus.confirm import note_ramp, ramp_keys
from fcmaster.bus.intents import learn
from fcmaster.bus.rotation import Rotation
from fcmaster.bus.steps import DriveSlot, Report, Step, StepKind
from fcmaster.bus.unconfirmed import Confirmations
from fcmaster.protocol.codec import DriveCodec, Reply


class Hearing:
    """Takes in what each valid reply says about its drive."""

    def __init__(self, codec: DriveCodec, rotation: Rotation, confirming: Confirmations) -> None:
        self._codec = codec
        self._rotation = rotation
        self._confirming = confirming
        self._ramp_keys = ramp_keys(codec)  # read from each bus-controlled drive once online
        self._adoption = Adoption(codec)

    def heard(self, slot: DriveSlot, step: Step, reply: Reply, now: float, report: Report) -> bool:
        """Take in what ``reply`` says about its drive; whether it shows a new trip."""
        kind = None if step.kind is StepKind.COMMAND else step.kind
        self._rotation.heard(slot, kind, now, report)
        learn(slot, reply)
        if slot.plan.control:
            self._adoption.heard(slot, reply, step.exchange.parameter)
        keys = self._ramp_keys
        if keys is not None and slot.plan.control:
            if not slot.ramps_asked:
                slot.ramps_asked = True
                slot.urgent_reads.extend(keys)
            if reply.value is not None:
                note_ramp(slot, keys, reply)
        conditions = reply.conditions
        if conditions is not None and conditions.kind == "alarm":
            slot.alarms[conditions.source] = tuple(c.text for c in conditions.active)
            slot.alarms_read = True
        status = reply.status
        if status is None:
            if slot.confirming and conditions is not None:
                self._confirming.judge(slot, now, report)
            return False
        alarms_changed = status.fault != slot.fault
        warnings_changed = status.warning != slot.warning
        tripped = status.fault and not slot.fault
        slot.fault, slot.warning = status.fault, status.warning
        slot.local, slot.status_word = not status.accepts_bus_control, status.word
        if tripped:
            slot.alarms_read = False  # which alarm it is comes with the next read of its word
        if slot.confirming:
            self._confirming.judge(slot, now, report)
        if alarms_changed or warnings_changed:
            for key in self._codec.condition_parameters(
                alarms=alarms_changed, warnings=warnings_changed
            ):
                if key not in slot.urgent_reads:
                    slot.urgent_reads.append(key)
        return tripped
