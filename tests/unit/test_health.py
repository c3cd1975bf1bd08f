"""The daemon's health figures: the collector's pauses, and the lines' timer lateness."""

from __future__ import annotations

import gc

from fcmaster import health
from fcmaster.adapters import metrics
from fcmaster.bus.plan import DrivePlan
from tests.unit.bus.bench import T0, bench


def test_each_collection_is_timed_once_watched() -> None:
    health.watch_gc()
    health.watch_gc()  # once per process, however often asked
    before = health.gc_pauses()
    assert before is not None
    gc.collect()
    gc.collect()
    after = health.gc_pauses()
    assert after is not None
    assert after["count"] == before["count"] + 2
    assert after["sum"] > before["sum"]


def test_freezing_moves_what_start_up_built_out_of_the_collectors_way() -> None:
    try:
        frozen = health.freeze_start_up()
        assert frozen == gc.get_freeze_count() > 0
    finally:
        health.thaw()
    assert gc.get_freeze_count() == 0


async def test_a_lines_pauses_are_counted_as_timers_and_on_time_in_virtual_time() -> None:
    b = bench(DrivePlan(name="a", address=1))
    async with b.master:
        await b.clock.run_until(T0 + 1.0)
    lateness = b.master.stats.wakeup_lateness
    # One pause before every request but the first, each ending exactly on time here.
    assert lateness.count == len(b.transport.sent) - 1
    assert lateness.sum == 0.0
    assert lateness.counts[0] == lateness.count


async def test_the_exposition_carries_the_gc_histogram_when_given() -> None:
    assert "fcmaster_gc_pause_seconds" not in await metrics.render_async([], [], None)
    buckets = [{"le": 0.001, "count": 2}, {"le": float("inf"), "count": 3}]
    pauses = {"buckets": buckets, "sum": 0.5, "count": 3}
    text = await metrics.render_async([], [], None, gc_pauses=pauses)
    assert 'fcmaster_gc_pause_seconds_bucket{le="0.001"} 2' in text
    assert 'fcmaster_gc_pause_seconds_bucket{le="+Inf"} 3' in text
    assert "fcmaster_gc_pause_seconds_count 3" in text
