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


async def test_an_unchanged_reply_is_the_same_reply_and_a_changed_one_is_read_anew() -> None:
    # One monitored value: every poll of the drive is the same request.
    b = bench(DrivePlan(name="m", address=3, monitor=("16-13",)))
    drive = b.drives[3]
    async with b.master:
        await b.clock.run_until(T0 + 0.5)
        drive.parameters[1613] = 123  # the value read changes: the reply's bytes change
        await b.clock.run_until(T0 + 1.0)
    replies = [reply for name, reply, _, _ in b.observer.replies if name == "m"]
    values = [r.value.raw if r.value is not None else None for r in replies]
    # The replies before the change are one object (the first may differ: the drive was
    # not adopted yet), and those after it another, read from the new bytes.
    changed = values.index(123)
    assert changed > 2
    before, after = replies[1:changed], replies[changed:]
    assert all(r is replies[1] for r in before)
    assert all(r is after[0] for r in after)
    assert after[0] is not replies[1]
    assert all(v != 123 for v in values[:changed])
    assert all(v == 123 for v in values[changed:])
