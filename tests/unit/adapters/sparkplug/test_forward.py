"""The store-and-forward queue: what counts as delivered, and bdSeq kept on disk."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

from fcmaster.adapters.sparkplug.forward import Forward, next_bd_seq
from fcmaster.adapters.sparkplug.metrics import Reading
from fcmaster.adapters.sparkplug.payload import DataType


def hz(value: float) -> dict[str, Reading]:
    return {"Output Frequency": Reading(DataType.DOUBLE, value, "", int(value * 1000))}


async def written(forward: Forward, count: int) -> None:
    """Until the writer's thread has committed ``count`` rows."""
    async with asyncio.timeout(10):
        while forward.writer.written < count:  # noqa: ASYNC110 - a thread's counter
            await asyncio.sleep(0.01)


async def settled(forward: Forward) -> list[float]:
    """Drain the backlog as the adapter does (everything published is taken as delivered)."""
    out: list[float] = []
    while True:
        changes, through = await forward.backlog()
        for change in changes:
            out.extend(float(r.value or 0) for _, r in change.readings)
        await forward.settle(through)
        if not changes:
            return out


async def test_only_what_a_barrier_confirmed_live_is_not_replayed(tmp_path: Path) -> None:
    store = str(tmp_path / "sf.db")
    forward = Forward(store, max_bytes=1 << 20, max_age_s=3600)
    forward.start()
    forward.record("b", "pump-1", hz(1.0), time.time())  # while the host was away
    forward.session_live()
    forward.record("b", "pump-1", hz(2.0), time.time())  # live, confirmed
    forward.confirm(forward.last_n)
    forward.record(
        "b", "pump-1", hz(3.0), time.time()
    )  # live, never confirmed: the connection failed
    await written(forward, 3)
    assert await settled(forward) == [1.0]  # the unconfirmed live one may still be confirmed
    forward.session_ended()
    assert await settled(forward) == [3.0]  # not now: the connection failed
    forward.close()

    again = Forward(store, max_bytes=1 << 20, max_age_s=3600)  # a restart: nothing was left
    again.start()
    again.record("b", "pump-1", hz(4.0), time.time())
    await written(again, 1)
    assert await settled(again) == [4.0]
    again.close()


def test_bdseq_follows_the_last_one_used_modulo_256_across_restarts(tmp_path: Path) -> None:
    path = tmp_path / "sf.db.bdseq"
    assert next_bd_seq(path, None) == 0
    assert next_bd_seq(path, None) == 1  # a restart reads the file
    path.write_text("255\n")
    assert next_bd_seq(path, None) == 0
    assert next_bd_seq(path, 41) == 42  # in the process, the last one it used
    assert path.read_text() == "42\n"
    assert next_bd_seq(None, None) == 0
