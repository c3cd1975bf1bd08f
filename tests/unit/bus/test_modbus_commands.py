"""Modbus RTU drives commanded through their profiles, in virtual time, as a plant meets them.

A gateway restarted under a drive running in reverse adopts it in reverse, so a reference
change never turns the motor round; a command the drive's profile cannot carry is refused
before anything is sent and the line goes on; a CiA 402 drive that left operation while
commanded to run is walked through its enable sequence again by the next start.
"""

from __future__ import annotations

import dataclasses

from fcmaster.bus.commands import Outcome
from fcmaster.bus.intents import learn
from fcmaster.bus.plan import DrivePlan
from fcmaster.bus.steps import DriveSlot
from fcmaster.protocol.codec import DriveStatus, Reply
from fcmaster.protocol.modbus_rtu import WriteSingle, decode_request
from fcmaster.protocol.modbus_rtu.profile import Register
from fcmaster.protocol.modbus_rtu.profiles import BUILT_IN
from fcmaster.sim.settings import DriveSettings
from tests.fakes import Sent, VirtualClock
from tests.orders import orders
from tests.unit.bus.bench import T0
from tests.unit.bus.modbus_line import SimLine, master_on, sim_line

BAUDRATE = 19200
ABB = DrivePlan(name="abb", address=1, control=True, profile=BUILT_IN["abb-drives"])
YASKAWA = DrivePlan(name="yaskawa", address=4, control=True, profile=BUILT_IN["yaskawa-memobus"])
ATV = DrivePlan(name="atv", address=3, control=True, profile=BUILT_IN["altivar-cia402"])


def _writes(sent: list[Sent], address: int, register: int) -> list[int]:
    """The values written to ``register`` of drive ``address``, in order."""
    requests = [decode_request(s.data) for s in sent]
    return [
        r.value
        for r in requests
        if isinstance(r, WriteSingle) and (r.address, r.register) == (address, register)
    ]


async def _run_in_reverse(line: SimLine, drive: DrivePlan) -> None:
    """A former gateway started ``drive`` and turned it to reverse, then went away."""
    _, master = master_on(line, BAUDRATE, drive)
    async with master:
        assert (await line.clock.complete(orders(master, drive.name).start(frequency_hz=20))).ok
        assert (await line.clock.complete(orders(master, drive.name).reverse())).ok
        await line.clock.run_for(3.0)
    (sim,) = line.drives.values()
    assert sim.motor.frequency_hz < -19.0  # running in reverse as the new gateway starts


async def test_a_restart_under_an_abb_drive_in_reverse_keeps_it_in_reverse() -> None:
    line = sim_line(VirtualClock(T0), BAUDRATE, ABB)
    await _run_in_reverse(line, ABB)
    transport, master = master_on(line, BAUDRATE, ABB)
    async with master:
        await line.clock.run_for(1.0)
        result = await line.clock.complete(orders(master, "abb").set_reference(frequency_hz=35))
        await line.clock.run_for(3.0)
    assert result.outcome is Outcome.DONE
    # ACT1/REF1 are signed (20000 = 100 %): 35 Hz in reverse is -14000, never +14000
    assert _writes(transport.sent, ABB.address, 1) == [0x10000 - 14000]
    assert line.drives[ABB.address].motor.frequency_hz < -30.0


async def test_a_restart_under_a_yaskawa_drive_in_reverse_never_runs_it_forward() -> None:
    # Its output frequency is a magnitude: only its status says the direction.
    line = sim_line(VirtualClock(T0), BAUDRATE, YASKAWA)
    await _run_in_reverse(line, YASKAWA)
    transport, master = master_on(line, BAUDRATE, YASKAWA)
    async with master:
        await line.clock.run_for(1.0)
        result = await line.clock.complete(orders(master, "yaskawa").set_reference(frequency_hz=35))
        await line.clock.run_for(3.0)
    assert result.outcome is Outcome.DONE
    words = _writes(transport.sent, YASKAWA.address, 1)
    assert words
    assert set(words) == {0x0002}
    assert line.drives[YASKAWA.address].motor.frequency_hz < -30.0


def test_a_magnitude_never_says_forward() -> None:
    slot = DriveSlot(ABB, sequence=(None,))
    running = DriveStatus(word=0, running=True, fault=False, warning=False, at_reference=True)
    learn(slot, Reply(address=1, status=dataclasses.replace(running, reverse=True)))
    learn(slot, Reply(address=1, output_frequency_hz=30.0))  # Mitsubishi's, ENC's: unsigned
    assert slot.reverse is True
    learn(slot, Reply(address=1, status=running, output_frequency_hz=30.0, output_signed=True))
    assert slot.reverse is False  # a signed reading says it where the status does not


UNSIGNED = DrivePlan(
    name="mine",
    address=1,
    control=True,
    profile=dataclasses.replace(
        BUILT_IN["yaskawa-memobus"],
        name="my-vfd",
        commands={k: v for k, v in BUILT_IN["yaskawa-memobus"].commands.items()
                  if k != "start_reverse"},
        reference=Register(address=0x0002, scale=0.01, unit="Hz"),
    ),
)  # fmt: skip


async def test_a_command_the_profile_cannot_carry_is_refused_and_the_line_goes_on() -> None:
    clock = VirtualClock(T0)
    line = sim_line(clock, BAUDRATE, UNSIGNED)
    transport, master = master_on(line, BAUDRATE, UNSIGNED)
    async with master:
        await clock.run_for(0.5)
        drive = orders(master, "mine")
        assert (await clock.complete(drive.start(frequency_hz=20))).ok
        sent = len(transport.sent)
        reverse = await clock.complete(drive.reverse())
        coast = await clock.complete(drive.coast())
        await clock.run_for(1.0)
        assert master.is_up
    assert (reverse.outcome, coast.outcome) == (Outcome.INVALID, Outcome.INVALID)
    assert "no way to run in reverse" in reverse.reason
    assert "coast" in coast.reason
    assert master.stats.crashes == 0
    assert 0x0002 not in _writes(transport.sent[sent:], 1, 1)  # nothing of either went out
    assert line.drives[1].motor.frequency_hz > 19.0  # and the motor runs on as it did


async def test_a_cia402_drive_that_left_operation_is_enabled_again_by_a_start() -> None:
    clock = VirtualClock(T0)
    line = sim_line(clock, BAUDRATE, ATV, settings={3: DriveSettings(profile=ATV.profile)})
    transport, master = master_on(line, BAUDRATE, ATV)
    async with master:
        await clock.run_for(0.5)
        drive = orders(master, "atv")
        assert (await clock.complete(drive.start(frequency_hz=10))).ok
        # Out of operation behind the gateway's back (a local stop, STO, a power cut):
        # its state machine falls to "switch on disabled".
        line.drives[3].machine.write(0x0000)
        await clock.run_for(1.0)
        sent = len(transport.sent)
        again = await clock.complete(drive.start(frequency_hz=10))
    assert again.outcome is Outcome.DONE, again.reason
    assert _writes(transport.sent[sent:], 3, 8501)[:3] == [0x0006, 0x0007, 0x000F]


async def test_the_control_word_and_reference_are_not_parameters() -> None:
    clock = VirtualClock(T0)
    line = sim_line(clock, BAUDRATE, ATV)
    transport, master = master_on(line, BAUDRATE, ATV)
    async with master:
        await clock.run_for(0.5)
        drive = orders(master, "atv")
        reference = await clock.complete(drive.write("hr8502", 90.0))  # LFR, beyond 50 Hz
        word = await clock.complete(drive.write("hr8501", 15.0))  # CMD: enable operation
        accel = await clock.complete(drive.write("hr9001", 5.0))  # ACC: a parameter
    assert (reference.outcome, word.outcome) == (Outcome.INVALID, Outcome.INVALID)
    assert "set_reference" in reference.reason
    assert accel.outcome is Outcome.DONE
    assert _writes(transport.sent, 3, 8502) == []  # never a reference, the limits unpassed
    assert 0x000F not in _writes(transport.sent, 3, 8501)  # the stopped drive's words only
