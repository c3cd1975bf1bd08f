"""Line statistics: the histograms, utilisation and the counters a running master keeps."""

from __future__ import annotations

import pytest

from fcmaster.bus.plan import DrivePlan
from fcmaster.bus.stats import LATENCY_BOUNDS, Histogram, LineStats
from tests.unit.bus.bench import PARAMETER, T0, bench, exchange_s
from tests.unit.bus.fcdrive import FcDrive


def test_histogram_counts_a_value_on_a_bound_in_that_bucket() -> None:
    histogram = Histogram((0.01, 0.1))
    for value in (0.005, 0.01, 0.05, 0.1, 0.5):
        histogram.observe(value)
    assert histogram.counts == [2, 2, 1]
    assert histogram.to_json() == {
        "buckets": [
            {"le": 0.01, "count": 2},
            {"le": 0.1, "count": 4},
            {"le": float("inf"), "count": 5},
        ],
        "count": 5,
        "sum": pytest.approx(0.665),
    }


def test_histogram_memory_is_fixed_whatever_it_observes() -> None:
    histogram = Histogram(LATENCY_BOUNDS)
    for n in range(10_000):
        histogram.observe(n / 1000)
    assert len(histogram.counts) == len(LATENCY_BOUNDS) + 1
    assert histogram.count == 10_000


@pytest.mark.parametrize(
    ("up_since", "busy_s", "now", "expected"),
    [
        pytest.param(None, 5.0, 10.0, 0.0, id="never-up"),
        pytest.param(10.0, 0.0, 10.0, 0.0, id="just-up"),
        pytest.param(0.0, 2.5, 10.0, 0.25, id="quarter"),
        pytest.param(0.0, 12.0, 10.0, 1.0, id="clamped"),
    ],
)
def test_utilisation_is_busy_time_over_time_up(
    up_since: float | None, busy_s: float, now: float, expected: float
) -> None:
    stats = LineStats(up_since=up_since, busy_s=busy_s)
    assert stats.utilisation(now) == expected


async def test_master_counts_requests_replies_timeouts_and_latency_per_drive() -> None:
    b = bench(
        DrivePlan(name="a", address=1),
        DrivePlan(name="dead", address=2),
        fc=[FcDrive(1), FcDrive(2, silent=True)],
        offline_after=2,
    )
    async with b.master:
        await b.clock.run_until(T0 + 1.0)
    stats = b.master.stats
    sent = b.transport.sent
    to_a = sum(1 for s in sent if s.data[2] == 0x81)
    assert stats.requests == len(sent)
    assert stats.drives["a"].requests == to_a
    assert stats.drives["a"].replies in (to_a, to_a - 1)  # the last one may be in flight
    assert stats.drives["a"].last_latency_s == pytest.approx(exchange_s(PARAMETER, PARAMETER))
    # One poll: a drive that never answered is not polled as if it were there.
    assert stats.drives["dead"].timeouts == stats.timeouts == 1
    assert stats.replies == stats.drives["a"].replies
    assert stats.latency.count == stats.replies
    assert stats.turnaround.counts[0] == stats.turnaround.count  # no overhead in virtual time
    document = stats.to_json(b.clock.now())
    assert document["drives"]["dead"]["timeouts"] == 1
    assert document["requests"] == len(sent)
    assert 0.9 < document["utilisation"] <= 1.0  # the line is never idle
