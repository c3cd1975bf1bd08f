"""What every protocol's faulty-line test checks once its commands have ended."""

from __future__ import annotations

from collections.abc import Sequence

from fcmaster.bus.commands import CommandResult, Outcome
from fcmaster.bus.stats import LineStats
from fcmaster.sim.line import LineCounters


def assert_faults_counted_and_no_command_lost(
    results: Sequence[CommandResult],
    stats: LineStats,
    counters: LineCounters,
    *,
    commands: int,
    at_least_done: int,
) -> None:
    """Each of ``commands`` ended once, retries carried most through, and the faults the
    simulator injected show in the master's counters without a reply being invented."""
    assert len(results) == commands
    assert all(r.outcome in (Outcome.DONE, Outcome.TIMEOUT) for r in results)
    assert sum(r.outcome is Outcome.DONE for r in results) >= at_least_done
    assert stats.timeouts > 0  # dropped and corrupted replies showed up as timeouts
    assert stats.checksum_errors + stats.noise_bytes > 0  # and as counted noise
    assert counters.requests >= stats.replies  # no reply was invented
