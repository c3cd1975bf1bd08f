"""The Link's flight recorder: the last 32 frames and events, oldest first, after wrapping."""

from __future__ import annotations

import itertools

from fcmaster.bus.link import RECORDED
from fcmaster.bus.plan import DrivePlan
from tests.unit.bus.bench import T0, bench

M = DrivePlan(name="m", address=3)


async def test_the_recorder_keeps_the_last_frames_in_order_after_wrapping() -> None:
    b = bench(M)
    async with b.master:
        await b.clock.run_until(T0 + 1.0)
        frames = b.master.recent_frames
    sent = b.transport.sent
    assert len(sent) > RECORDED  # the rings went round more than once
    assert len(frames) == RECORDED
    kinds = [f.split()[0] for f in frames]
    assert set(kinds) == {"tx", "rx"}
    assert all(a != b for a, b in itertools.pairwise(kinds))  # request, reply, …
    recorded_tx = [f for f in frames if f.startswith("tx ")]
    assert recorded_tx == ["tx " + s.data.hex(" ") for s in sent[-len(recorded_tx) :]]
