import asyncio

import pytest

from fcmaster.adapters.readlimit import ReadsBusy, ViewerReads
from tests.fakes import FakeClock


async def test_beyond_the_waiting_room_a_reader_is_told_to_come_back() -> None:
    reads = ViewerReads(FakeClock(), gap_s=0.0, max_waiting=1)
    inside = asyncio.Event()
    leave = asyncio.Event()

    async def reader() -> None:
        async with reads.turn("line1"):
            inside.set()
            await leave.wait()

    first = asyncio.create_task(reader())
    await inside.wait()
    second = asyncio.create_task(reader())  # waits its turn
    await asyncio.sleep(0)
    with pytest.raises(ReadsBusy, match="1 viewer reads already wait on line1"):
        async with reads.turn("line1"):
            pass
    async with reads.turn("line2"):  # another line is not held up
        pass
    leave.set()
    await asyncio.gather(first, second)


async def test_viewer_reads_on_a_line_are_spaced_by_the_gap_on_the_injected_clock() -> None:
    clock = FakeClock(start=100.0)
    reads = ViewerReads(clock, gap_s=0.5)
    started: list[tuple[str, float]] = []
    for line in ("line1", "line1", "line1", "line2"):
        async with reads.turn(line):
            started.append((line, clock.now()))
    assert started == [("line1", 100.0), ("line1", 100.5), ("line1", 101.0), ("line2", 101.0)]
