"""The frame log a capture follows: numbered frames, no gaps, misses counted."""

from __future__ import annotations

from fcmaster.bus.frame_log import RX, TX, FrameLog
from fcmaster.bus.plan import DrivePlan
from tests.fakes import FakeClock, Timed
from tests.unit.bus.bench import bench
from tests.unit.bus.fcdrive import FcDrive, FcLine


def test_a_follower_gets_every_frame_once_in_order() -> None:
    log = FrameLog(FakeClock().wall, length=8)
    log.add(TX, b"\x02\x01", 1.0)
    log.add(RX, b"\x02\x81", 1.5)
    first = log.since(0)
    assert [(seq, d, mono, data) for seq, d, mono, _, data in first.frames] == [
        (0, "tx", 1.0, b"\x02\x01"),
        (1, "rx", 1.5, b"\x02\x81"),
    ]
    assert (first.next, first.missed) == (2, 0)
    assert log.since(first.next).frames == []
    log.add(TX, b"\x03", 2.0)
    again = log.since(first.next)
    assert [f[0] for f in again.frames] == [2]
    assert again.next == 3


def test_frames_carry_the_wall_clock_time_they_were_logged() -> None:
    clock = FakeClock(start=5.0)
    log = FrameLog(clock.wall)
    before = clock.wall()
    log.add(TX, b"x", 5.0)
    clock.time = 6.0
    log.add(RX, b"y", 6.0)
    walls = [frame[3] for frame in log.since().frames]
    assert walls == [before, before + 1.0]  # the clock's wall time when each was added


def test_a_follower_that_fell_behind_the_ring_learns_how_many_it_missed() -> None:
    log = FrameLog(FakeClock().wall, length=4)
    for n in range(10):
        log.add(TX, bytes([n]), float(n))
    got = log.since(3)
    assert got.missed == 3  # frames 3, 4 and 5 left the ring
    assert [f[4] for f in got.frames] == [bytes([n]) for n in (6, 7, 8, 9)]
    assert got.next == 10


def test_numbers_from_before_a_restart_start_the_follower_afresh() -> None:
    log = FrameLog(FakeClock().wall)
    assert (log.since(50).frames, log.since(50).next) == ([], 0)
    log.add(RX, b"a", 0.0)
    got = log.since(50)
    assert [f[0] for f in got.frames] == [0]
    assert (got.next, got.missed) == (1, 0)


async def test_the_link_logs_each_request_and_what_came_back_when_it_came() -> None:
    line = FcLine(FcDrive(1))
    replies: list[bytes] = []

    def noisy(request: bytes) -> Timed | None:
        reply = line(request)
        assert isinstance(reply, bytes)
        replies.append(reply)
        return Timed(((0.005, b"\xff"), (0.020, reply)))  # a noise byte, then the reply

    bus = bench(DrivePlan(name="d1", address=1), responder=noisy)
    async with bus.master:
        await bus.clock.run_for(0.3)
    frames = bus.master.frames.since(0).frames
    sent = bus.transport.sent
    assert len(sent) > 5
    logged = [(direction, mono, data) for _, direction, mono, _, data in frames]
    expected = []
    for request, reply in zip(sent[:-1], replies, strict=False):  # the last may be under way
        expected += [
            ("tx", request.at, request.data),
            ("rx", request.at + 0.005, b"\xff"),
            ("rx", request.at + 0.020, reply),
        ]
    assert logged[: len(expected)] == expected
    assert logged[len(expected)] == ("tx", sent[-1].at, sent[-1].data)
