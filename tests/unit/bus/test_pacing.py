"""A drive profile's pacing on a Modbus line, in virtual time: after a parameter write the
Yaskawa drive is sent nothing for its profile's wait, while the line's other drive is polled.

The drives are the simulator's, behind a scripted wire; the Yaskawa one is deaf for its
profile's wait after a parameter write, as the family's drives are, so a request sent to it
too soon goes unanswered (and is counted).
"""

from __future__ import annotations

import pytest

from fcmaster.bus.commands import Outcome
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan
from fcmaster.protocol.modbus_rtu import WriteSingle, decode_request
from fcmaster.protocol.modbus_rtu.profile import DriveProfile
from fcmaster.protocol.modbus_rtu.profiles import BUILT_IN
from fcmaster.sim.settings import DriveSettings
from tests.fakes import ScriptedTransport, Sent, Timed, VirtualClock
from tests.orders import orders
from tests.unit.bus.bench import T0
from tests.unit.bus.modbus_line import SimLine, master_on, sim_line

YASKAWA: DriveProfile = BUILT_IN["yaskawa-memobus"]
ABB: DriveProfile = BUILT_IN["abb-drives"]
WAIT_S = YASKAWA.pacing.after_write_s
BAUDRATE = 115200  # an ABB poll takes less than the wait: several go meanwhile
ACCEL = "hr512"  # C1-01 acceleration time (0200H)


def _line(*drives: DrivePlan) -> tuple[VirtualClock, ScriptedTransport, BusMaster, SimLine]:
    clock = VirtualClock(T0)
    settings = {
        d.address: DriveSettings(profile=d.profile, parameters={ACCEL: 100}) for d in drives
    }
    line = sim_line(clock, BAUDRATE, *drives, settings=settings)
    transport, master = master_on(line, BAUDRATE, *drives)
    return clock, transport, master, line


def _is_accel_write(sent: Sent) -> bool:
    request = decode_request(sent.data)
    return request.address == 4 and isinstance(request, WriteSingle) and request.register == 512


YASKAWA_DRIVE = DrivePlan(name="yaskawa", address=4, control=True, profile=YASKAWA)
ABB_DRIVE = DrivePlan(name="abb", address=1, profile=ABB)


async def test_after_a_paced_write_its_drive_waits_while_the_other_is_polled() -> None:
    clock, transport, master, line = _line(YASKAWA_DRIVE, ABB_DRIVE)
    async with master:
        await clock.run_until(T0 + 0.3)
        result = await clock.complete(orders(master, "yaskawa").write(ACCEL, 20.0))
        await clock.run_for(0.2)
    assert result.outcome is Outcome.DONE
    sent = transport.sent
    (index,) = [i for i, s in enumerate(sent) if _is_accel_write(s)]
    write = sent[index]
    assert write.reply_at is not None
    ready = write.reply_at + WAIT_S
    after = sent[index + 1 :]
    to_yaskawa = [s for s in after if s.data[0] == 4]
    # the Yaskawa drive hears nothing before its wait is over...
    assert to_yaskawa[0].at >= ready
    # ...and gets the line's first request once it is (the round comes back to it)
    assert next(s for s in after if s.at >= ready).data[0] == 4
    # meanwhile the other drive was polled, from the end of the write's reply on
    waiting = [s for s in after if s.at < ready]
    assert len(waiting) >= 2
    assert all(s.data[0] == 1 for s in waiting)
    assert waiting[0].at == pytest.approx(write.reply_at + 0.00175)  # t3.5 above 19200
    # and every request found its drive listening
    assert line.unheard == 0
    assert all(s.reply_at is not None for s in sent)


async def test_a_drive_alone_on_its_line_is_sent_its_next_request_when_the_wait_ends() -> None:
    clock, transport, master, line = _line(YASKAWA_DRIVE)
    async with master:
        await clock.run_until(T0 + 0.3)
        result = await clock.complete(orders(master, "yaskawa").write(ACCEL, 20.0))
        await clock.run_for(0.2)
    assert result.outcome is Outcome.DONE
    sent = transport.sent
    (index,) = [i for i, s in enumerate(sent) if _is_accel_write(s)]
    write, following = sent[index], sent[index + 1]
    assert write.reply_at is not None
    assert following.at == pytest.approx(write.reply_at + WAIT_S)  # the line idle meanwhile
    assert line.unheard == 0


async def test_the_retry_of_a_paced_write_whose_answer_was_lost_waits_too() -> None:
    clock, transport, master, line = _line(YASKAWA_DRIVE, ABB_DRIVE)
    respond = transport.responder
    lost: list[float] = []

    def losing_the_first_answer(request: bytes) -> bytes | Timed | None:
        reply = respond(request)
        if not lost and _is_accel_write(Sent(0.0, request)):
            lost.append(clock.now())
            return None  # the drive took the write; its answer is lost on the wire
        return reply

    transport.responder = losing_the_first_answer
    async with master:
        await clock.run_until(T0 + 0.3)
        result = await clock.complete(orders(master, "yaskawa").write(ACCEL, 20.0))
    assert result.outcome is Outcome.DONE
    first, retry = [s for s in transport.sent if _is_accel_write(s)]
    assert first.deadline is not None
    assert retry.at >= first.deadline + WAIT_S
    assert line.unheard == 0
