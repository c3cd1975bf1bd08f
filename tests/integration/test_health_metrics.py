"""The daemon's health on a real /metrics scrape: `fcmaster run` against `fcmaster sim` on a pty.

Two histograms tell whether the process keeps its lines' time: how late each line's timers
fired (the end of a pause, a reply's deadline), and how long the garbage collector stopped
the process. Both must be there, with counts that grow and contents a working line shows.
"""

from __future__ import annotations

import itertools
import re
from pathlib import Path
from typing import Any

import httpx

from tests.integration.daemon_harness import Child, child, until
from tests.integration.ports import free_port

# At 9600 baud the FC pause (2 characters, 2.3 ms) ends in a timer, and the absent drive's
# probes end in their deadline's.
CONFIG = """
buses:
  - name: line1
    port: {tty}
    baudrate: 9600
    drives:
      - {{name: pump-1, address: 1}}
      - {{name: pump-2, address: 2}}
{absent}
http:
  listen: 127.0.0.1:{port}
  anonymous: viewer
metrics: {{enabled: true}}
logging: {{level: info, format: json}}
"""


ABSENT = "      - {name: absent-3, address: 3}"


def histogram(
    text: str, name: str, selector: str
) -> tuple[list[tuple[float, float]], float, float]:
    """The buckets (upper bound, cumulative count), sum and count of one histogram."""
    inner = f"{selector}," if selector else ""
    buckets = [
        (float(le), float(count))
        for le, count in re.findall(
            rf'^{name}_bucket\{{{re.escape(inner)}le="([^"]+)"\}} (\S+)$', text, re.MULTILINE
        )
    ]
    braces = f"{{{selector}}}" if selector else ""
    total = re.search(rf"^{name}_sum{re.escape(braces)} (\S+)$", text, re.MULTILINE)
    count = re.search(rf"^{name}_count{re.escape(braces)} (\S+)$", text, re.MULTILINE)
    assert total is not None, f"{name}_sum{braces} not in the scrape"
    assert count is not None, f"{name}_count{braces} not in the scrape"
    return buckets, float(total.group(1)), float(count.group(1))


def plausible(buckets: list[tuple[float, float]], total: float, count: float) -> None:
    """Cumulative buckets ending in +Inf at the count, and a non-negative sum."""
    assert buckets, "no buckets"
    assert buckets[-1][0] == float("inf")
    assert buckets[-1][1] == count
    assert all(a[1] <= b[1] for a, b in itertools.pairwise(buckets))
    assert all(a[0] < b[0] for a, b in itertools.pairwise(buckets))
    assert total >= 0.0


async def test_metrics_show_the_lines_timer_lateness_and_the_collectors_pauses(
    tmp_path: Path,
) -> None:
    tty, port = tmp_path / "ttyLINE1", free_port()
    config, simulated = tmp_path / "plant.yaml", tmp_path / "sim.yaml"
    config.write_text(CONFIG.format(tty=tty, port=port, absent=ABSENT))
    simulated.write_text(CONFIG.format(tty=tty, port=port, absent=""))  # drive 3 is not there
    url = f"http://127.0.0.1:{port}"
    async with (
        child("sim", "--config", str(simulated), log=tmp_path / "sim.log") as sim,
        httpx.AsyncClient(base_url=url, timeout=10) as client,
    ):
        await sim.readline()
        async with child("run", "--config", str(config), log=tmp_path / "run.log") as daemon:

            async def scrape(least: int) -> str | None:
                response = await client.get("/metrics")
                text = response.text if response.status_code == 200 else ""
                if 'fcmaster_bus_wakeup_lateness_seconds_count{bus="line1"}' not in text:
                    return None
                _, _, count = histogram(text, "fcmaster_bus_wakeup_lateness_seconds", 'bus="line1"')
                return text if count >= least else None

            first = await until(lambda: scrape(20), "20 timers of line1", alive=daemon)
            later = await until(
                lambda: scrape(first_count(first) + 20), "more timers", alive=daemon
            )
            started = _started(daemon)
    buckets, total, count = histogram(later, "fcmaster_bus_wakeup_lateness_seconds", 'bus="line1"')
    plausible(buckets, total, count)
    assert count >= first_count(first) + 20  # it grows as the line runs
    assert total / count < 1.0  # late by a second on average would be a stalled daemon
    # The start-up collection before the freeze was timed, at least.
    buckets, total, count = histogram(later, "fcmaster_gc_pause_seconds", "")
    plausible(buckets, total, count)
    assert count >= 1
    assert 0.0 < total / count < 1.0
    assert started["gc_frozen"] > 10_000  # what start-up built: config, codecs, FastAPI


def first_count(text: str) -> int:
    return int(histogram(text, "fcmaster_bus_wakeup_lateness_seconds", 'bus="line1"')[2])


def _started(daemon: Child) -> dict[str, Any]:
    return next(e for e in daemon.log_events() if e.get("event") == "service.started")
