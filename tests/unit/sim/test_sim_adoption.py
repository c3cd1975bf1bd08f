"""A master restarted while its drives ramp: adoption takes over what each drive is doing.

Two BusMasters, one after the other, on the same simulated line in virtual time: the first
starts the drives and stops some of them on a long ramp, then vanishes mid-ramp as a killed
gateway does (no shutdown stop). The second adopts the line.

FC: every control word the second master puts on the wire is decoded: the drives ramping
down keep getting stop words and reach standstill, the ones at speed keep getting run words
at their speed. Mitsubishi and ENC, whose polls never command: a command that changes only
a drive's reference, sent while the drive ramps down or once it stands, never starts it.
"""

from __future__ import annotations

import asyncio

import pytest

from fcmaster.bus.codecs import codec_for, with_protocol_delay
from fcmaster.bus.commands import Outcome
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.danfoss_fc.framer import FcFramer
from fcmaster.protocol.danfoss_fc.profile import ControlWord, decode_reference
from fcmaster.protocol.danfoss_fc.telegram import decode_telegram
from fcmaster.protocol.framing import Frame
from fcmaster.sim import (
    DriveSettings,
    EncSimDrive,
    FcSimDrive,
    LineSettings,
    MitsubishiSimDrive,
    SimTransport,
    build_line,
)
from fcmaster.sim.line import SimLine
from tests.fakes import VirtualClock
from tests.orders import orders

ADDRESSES = (1, 2, 3, 4)
STOPPED = (1, 2)  # stopped by the first master, still ramping down when it dies
RAMP = {"3-42": 10.0}  # seconds from 3-03 to 0


class Wire:
    """Every valid control word on the line, per address, with the reference it carried."""

    def __init__(self, line: SimLine) -> None:
        self.framer = FcFramer()
        self.words: dict[int, list[tuple[int, float]]] = {a: [] for a in ADDRESSES}
        pass_on = line.write

        def record(data: bytes) -> None:
            self.framer.feed(data)
            while (piece := self.framer.next_frame()) is not None:
                if isinstance(piece, Frame):
                    telegram = decode_telegram(piece.data, from_drive=False)
                    if telegram.pcd1 & ControlWord.DATA_VALID and telegram.address in self.words:
                        reference = decode_reference(telegram.pcd2)
                        self.words[telegram.address].append((telegram.pcd1, reference))
            pass_on(data)

        line.write = record  # type: ignore[method-assign]

    def clear(self) -> None:
        for words in self.words.values():
            words.clear()


def runs(word: int) -> bool:
    """Whether a valid control word asks the motor to run (start, and no stop of any kind)."""
    needed = ControlWord.START | ControlWord.NO_COAST | ControlWord.NO_QUICK_STOP
    return word & (needed | ControlWord.NO_DC_BRAKE) == needed | ControlWord.NO_DC_BRAKE


def master_on(line: SimLine, clock: VirtualClock) -> BusMaster:
    plan = LinePlan(
        name="line1", port="sim://line1",
        drives=tuple(DrivePlan(name=f"d{a}", address=a, control=True) for a in ADDRESSES),
    )  # fmt: skip
    return BusMaster(plan, codec=FcCodec(), transport=SimTransport(line, clock), clock=clock)


async def test_a_drive_ramping_down_after_a_stop_is_adopted_stopping_and_one_at_speed_running() -> (
    None
):
    clock = VirtualClock()
    line = build_line(
        LineSettings(), [(a, DriveSettings(parameters=RAMP)) for a in ADDRESSES], clock=clock
    )
    drives = {d.address: d for d in line.drives if isinstance(d, FcSimDrive)}
    wire = Wire(line)
    first = master_on(line, clock)
    async with first:
        for a in ADDRESSES:
            started = await clock.complete(orders(first, f"d{a}").start(frequency_hz=40.0))
            assert started.ok, started.reason
        await clock.run_for(10.0)  # every drive at speed
        stops = [asyncio.ensure_future(orders(first, f"d{a}").stop()) for a in STOPPED]
        await clock.run_for(1.0)  # acknowledged, ramping down: about 36 Hz of 40
    for stop in stops:  # the gateway is gone: its stops never saw their drives stand
        await asyncio.wait([stop])
    for a in STOPPED:
        drives[a].advance(clock.now())
        assert 30.0 < drives[a].motor.frequency_hz < 40.0
    wire.clear()

    second = master_on(line, clock)
    async with second:
        await clock.run_for(12.0)
        for a in ADDRESSES:
            drives[a].advance(clock.now())
    for a in STOPPED:
        words = wire.words[a]
        assert words, f"drive {a} was never commanded after the restart"
        assert [hex(w) for w, _ in words if runs(w)] == [], f"drive {a} told to run again"
        assert drives[a].motor.frequency_hz == 0.0
        assert not drives[a].motor.output_on
    for a in set(ADDRESSES) - set(STOPPED):
        words = wire.words[a]
        assert words, f"drive {a} was never commanded after the restart"
        assert all(runs(w) for w, _ in words), f"drive {a} told to stop"
        assert {round(r, 1) for _, r in words} == {80.0}  # 40 Hz of 50: its present output
        assert drives[a].motor.frequency_hz == pytest.approx(40.0, abs=0.01)  # no jolt


# -- protocols whose polls never command: Mitsubishi, ENC --------------------------------------

RAMPS = {"mitsubishi": ("Pr.8", 2), "enc": ("F0.09", 1)}  # deceleration time, stop bits


def line_of(protocol: str, clock: VirtualClock) -> tuple[SimLine, LinePlan]:
    ramp, stopbits = RAMPS[protocol]
    settings = DriveSettings(parameters={ramp: 30.0})
    line = build_line(
        LineSettings(protocol=protocol, stopbits=stopbits),
        [(a, settings) for a in (1, 2)],
        clock=clock,
    )
    plan = with_protocol_delay(
        LinePlan(
            name="line1", port="sim://line1", protocol=protocol, stopbits=stopbits,
            drives=tuple(DrivePlan(name=f"d{a}", address=a, control=True) for a in (1, 2)),
        )
    )  # fmt: skip
    return line, plan


@pytest.mark.parametrize("protocol", sorted(RAMPS))
async def test_a_reference_after_a_restart_never_starts_a_drive_that_was_stopping(
    protocol: str,
) -> None:
    clock = VirtualClock()
    line, plan = line_of(protocol, clock)
    motors = {d.address: d for d in line.drives if isinstance(d, MitsubishiSimDrive | EncSimDrive)}

    def output(address: int) -> float:
        motors[address].advance(clock.now())
        return abs(motors[address].motor.frequency_hz)

    def master() -> BusMaster:
        return BusMaster(
            plan, codec=codec_for(plan), transport=SimTransport(line, clock), clock=clock
        )

    first = master()
    async with first:
        for name in ("d1", "d2"):
            started = await clock.complete(orders(first, name).start(frequency_hz=40.0))
            assert started.ok, started.reason
        await clock.run_for(30.0)  # both at speed
        stop = asyncio.ensure_future(orders(first, "d1").stop())
        await clock.run_for(1.0)  # d1 ramping down
    await asyncio.wait([stop])  # the gateway is gone
    killed_at = output(1)
    assert 30.0 < killed_at < 40.0
    # A process takes longer to start again than a reply still on the wire: the new master's
    # first telegram to each drive, its one attempt, does not run into the last one's reply.
    await clock.run_for(0.2)

    second = master()
    async with second:
        await clock.run_for(1.0)
        during = await clock.complete(orders(second, "d1").set_reference(frequency_hz=20.0))
        assert during.outcome is Outcome.TIMEOUT, during
        assert "output falling" in during.reason
        assert output(1) < killed_at  # still ramping down: no run command reached it
        await clock.run_for(30.0)
        assert output(1) == 0.0
        after = await clock.complete(orders(second, "d1").set_reference(frequency_hz=20.0))
        assert after.ok, after.reason
        await clock.run_for(10.0)
        assert output(1) == 0.0  # the reference is kept for a start; it started nothing
        at_speed = await clock.complete(orders(second, "d2").set_reference(frequency_hz=30.0))
        assert at_speed.ok, at_speed.reason
        await clock.run_for(10.0)
        assert output(2) == pytest.approx(30.0, abs=0.01)  # one at speed runs on
