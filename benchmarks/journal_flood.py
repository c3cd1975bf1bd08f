"""The journal's cost: per event, and to a line's rate under a flood of 1,000 events a second.

Run: ``python benchmarks/journal_flood.py [--rate 1000] [--seconds 5] [--cycles 4]
[--drives 8] [--baudrate 115200] [--out PATH]`` (about a minute; results in
``benchmarks/results/journal_flood.json`` by default).

Two figures:

1. The cost of one event, apart: a :class:`~fcmaster.journal.Journal` on a file (WAL,
   ``synchronous=FULL``) fed ``--events`` command results through a hub, a hundred at a
   time. On the loop, what a publication and the journal's task taking it cost per event
   (the row is made on the writer's thread); on the writer thread, the wall time from the
   first publication to the last event committed, per event, and the events per second that
   makes (batches of up to 1,000, one transaction each).
2. The line under a flood: a daemon (:class:`fcmaster.service.Service`, fcmaster's precise
   event loop) polls simulated FC drives on an in-process ``sim://`` line in real time with
   its journal on a file. Its transaction rate (the master's request counter over wall
   time) is measured in alternating windows of ``--seconds``: quiet, then flooded with
   ``--rate`` command results a second published to its hub (every 10 ms, a tenth of them),
   which the journal keeps. The change is the mean flooded rate against the mean quiet one;
   the spread among the quiet windows says how much of it is the machine's own noise.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import results_file

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.config import parse
from fcmaster.hub import Hub
from fcmaster.journal import Journal
from fcmaster.service import Service
from fcmaster.state import CommandCompleted
from fcmaster.store_settings import StoreSettings

now = time.perf_counter
EVENT = CommandCompleted(
    bus="line1",
    drive="d1",
    command=Command(action=Action.SET_REFERENCE, reference_pct=42.0, actor="bench"),
    result=CommandResult(outcome=Outcome.DONE, reason=""),
)


async def per_event(events: int, directory: Path) -> dict[str, Any]:
    """Figure 1: the loop's cost and the writer's per event."""
    hub = Hub()
    settings = StoreSettings(path=str(directory / "cost.db"))
    async with Journal(settings, hub, wall=time.time) as journal:
        await asyncio.sleep(0.2)  # the file opened, the writer waiting
        loop_s = 0.0
        started = now()
        for _ in range(events // 100):
            # On the loop: a hundred publications, and the journal's task taking them
            # (what that task does per event is all the loop pays for the journal).
            mark = now()
            for _ in range(100):
                hub.publish(EVENT)
            await asyncio.sleep(0)
            await asyncio.sleep(0)
            loop_s += now() - mark
        writer = journal.writer
        while writer.written + writer.dropped < events and now() - started < 120:  # noqa: ASYNC110
            await asyncio.sleep(0.001)  # (a thread writes: no event to wait on)
        wrote_s = now() - started
    return {
        "events": events,
        "loop_us_per_event": round(loop_s / events * 1e6, 2),
        "write_us_per_event": round(wrote_s / events * 1e6, 2),
        "events_per_s_written": round(events / wrote_s),
        "dropped": journal.writer.dropped,
    }


def fleet(drives: int, baudrate: int, journal: Path) -> str:
    lines = "\n".join(f"      - {{name: d{a}, address: {a}}}" for a in range(1, drives + 1))
    return (
        f"buses:\n  - name: line1\n    port: sim://line1\n    baudrate: {baudrate}\n"
        f"    response_delay_ms: 5\n    simulation: {{response_delay_ms: 5}}\n"
        f"    drives:\n{lines}\njournal: {{path: {journal}}}\n"
    )


async def flood(service: Service, rate: int, until: float) -> int:
    """Publish ``rate`` events a second to the service's hub until ``until``; how many."""
    sent = 0
    per_tick = max(1, rate // 100)
    due = now()
    while now() < until:
        for _ in range(per_tick):
            service.hub.publish(EVENT)
        sent += per_tick
        due += 0.01
        await asyncio.sleep(max(0.0, due - now()))
    return sent


async def line_rates(args: argparse.Namespace, directory: Path) -> dict[str, Any]:
    """Figure 2: the line's rate, quiet and flooded."""
    service = Service(parse(fleet(args.drives, args.baudrate, directory / "flood.db")))
    task = asyncio.create_task(service.run(install_signals=False))
    await service.hub.wait_for(
        lambda: all(s.online for s in service.fleet.snapshot()), timeout_s=30
    )
    await asyncio.sleep(1.0)
    master = service.masters["line1"]
    quiet: list[float] = []
    flooded: list[float] = []
    sent = 0
    for _ in range(args.cycles):
        for loaded in (False, True):
            before, started = master.stats.requests, now()
            until = started + args.seconds
            if loaded:
                sent += await flood(service, args.rate, until)
            else:
                await asyncio.sleep(args.seconds)
            rate = (master.stats.requests - before) / (now() - started)
            (flooded if loaded else quiet).append(rate)
    await asyncio.sleep(1.0)
    written, dropped = service.journal.writer.written, service.journal.writer.dropped
    service.stop()
    await task
    mean_quiet, mean_flooded = statistics.mean(quiet), statistics.mean(flooded)
    return {
        "rate_events_per_s": args.rate,
        "events_sent": sent,
        "journal_written": written,
        "journal_dropped": dropped,
        "quiet_tx_per_s": [round(r, 1) for r in quiet],
        "flooded_tx_per_s": [round(r, 1) for r in flooded],
        "change_pct": round((mean_flooded / mean_quiet - 1) * 100, 2),
        "quiet_spread_pct": round((max(quiet) - min(quiet)) / mean_quiet * 100, 2),
    }


async def main(args: argparse.Namespace) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        directory = Path(tmp)
        return {
            **results_file.provenance("journal_flood"),
            "settings": {
                "drives": args.drives,
                "baudrate": args.baudrate,
                "seconds": args.seconds,
                "cycles": args.cycles,
            },
            "per_event": await per_event(args.events, directory),
            "line_under_flood": await line_rates(args, directory),
            "load_average": os.getloadavg(),
        }


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rate", type=int, default=1000)
    parser.add_argument("--events", type=int, default=10_000)  # below the writer's queue bound
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--cycles", type=int, default=4)
    parser.add_argument("--drives", type=int, default=8)
    parser.add_argument("--baudrate", type=int, default=115200)
    parser.add_argument(
        "--out", type=Path, default=Path(__file__).parent / "results" / "journal_flood.json"
    )
    arguments = parser.parse_args()
    results_file.run_and_write(main(arguments), arguments.out)
