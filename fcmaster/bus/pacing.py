"""How long a drive is left alone after an exchange: its restart, or its family's pacing.

Some requests leave a drive unable to hear the next one for a while. A Mitsubishi inverter
reset restarts the drive (the exchange's ``deaf_s``): it hears nothing, and its output went
off with the restart, so its commanded intent becomes a stop. Some families need time after
a parameter write, or between the steps of a command sequence, before they answer again
(the exchange's ``settle_s``, from the drive profile's pacing: Yaskawa after a write).

Either way the drive's ``deaf_until`` says when it may next be addressed; until then the
planner sends it nothing, polls and commands alike, and serves the line's other drives
meanwhile (the queue and the rotation skip a drive that cannot hear yet, and the rotation's
wake-up includes the time it can again). The wait counts from when the exchange ended: the
reply's arrival, the request's end for one that gets no reply, or the deadline of one that
got none in time (a write whose reply was lost may still have been taken, so its retry
waits too).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

from fcmaster.bus.intents import restarted
from fcmaster.bus.steps import DriveSlot, Step


def leave_alone(
    step: Step, targets: Callable[[DriveSlot | None], Iterable[DriveSlot]], now: float
) -> None:
    """``step``'s exchange ended at ``now``: keep the drives it went to unaddressed as it asks.

    ``targets`` gives those drives from the step's slot (all of them for a broadcast); it is
    asked only when the exchange wants a wait, so a reply that does not costs nothing.
    """
    exchange = step.exchange
    if exchange.deaf_s > 0:
        for target in targets(step.slot):
            restarted(target, now + exchange.deaf_s)
    elif exchange.settle_s > 0:
        until = now + exchange.settle_s
        for target in targets(step.slot):
            target.deaf_until = max(target.deaf_until, until)
