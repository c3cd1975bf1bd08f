import asyncio

import pytest

from fcmaster.adapters.readlimit import ReadsBusy, ViewerReads


async def test_beyond_the_waiting_room_a_reader_is_told_to_come_back() -> None:
    reads = ViewerReads(gap_s=0.0, max_waiting=1)
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
