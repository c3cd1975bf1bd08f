"""Python function calls per transaction of fcmaster's BusMaster polling over a pty.

Run: ``python benchmarks/bus_calls.py [--seconds S] [--drives D] [--baudrate B] [--top K]``.

The same line as ``benchmarks/bus_pair.py`` (``benchmarks/bus.py``'s simulator on a pty,
monitor-only FC drives, every poll a 16-byte parameter telegram), with the master's
process under :mod:`cProfile` for S seconds after a warm-up:
the count of Python-level calls (and of C calls cProfile sees) per reply is the stable
figure, far less at the mercy of a shared machine's load than CPU seconds. The top
functions by call count follow. Benchmarks are not tests: nothing here passes or fails.
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import os
import pstats
import sys

import bus as harness

from fcmaster import logsetup
from fcmaster.bus.master import BusMaster
from fcmaster.clock import MonotonicClock, new_event_loop
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.transport.serial import SerialTransport


async def profile(case: harness.Case, path: str, seconds: float) -> tuple[pstats.Stats, int]:
    plan = case.line_plan(path)
    clock = MonotonicClock()
    transport = SerialTransport(path, baudrate=plan.baudrate, parity=plan.parity)
    profiler = cProfile.Profile()
    async with BusMaster(plan, codec=FcCodec(), transport=transport, clock=clock) as master:
        await harness.warmed_up(master)
        first = master.stats.replies
        profiler.enable()
        await asyncio.sleep(seconds)  # one wake-up of its own, not one per poll
        profiler.disable()
        replies = master.stats.replies - first
    return pstats.Stats(profiler), replies


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--drives", type=int, default=32)
    parser.add_argument("--baudrate", type=int, default=115200)
    parser.add_argument("--top", type=int, default=30)
    parser.add_argument("--python-only", action="store_true", help="list Python functions only")
    args = parser.parse_args(argv)
    logsetup.configure(level="warning")
    case = harness.Case(args.drives, args.baudrate, 0.005)
    with (
        harness.simulator(case.baudrate, case.delay_s, case.drives) as sim,
        asyncio.Runner(loop_factory=new_event_loop) as runner,
    ):
        stats, replies = runner.run(profile(case, sim.path, args.seconds))
    entries = stats.stats  # type: ignore[attr-defined]
    total = sum(nc for (_, nc, _, _, _) in entries.values())
    python = sum(
        nc for (file, _, _), (_, nc, _, _, _) in entries.items() if not file.startswith("~")
    )
    print(
        f"{args.drives} drives at {args.baudrate}: {replies} replies, "
        f"{python / replies:.1f} Python calls and {(total - python) / replies:.1f} C calls "
        f"per transaction; load {os.getloadavg()[0]:.2f}"
    )
    rows = sorted(entries.items(), key=lambda item: -item[1][1])
    if args.python_only:
        rows = [row for row in rows if not row[0][0].startswith("~")]
    rows = rows[: args.top]
    for (file, line, name), (_, calls, _, _, _) in rows:
        where = name if file.startswith("~") else f"{os.path.basename(file)}:{line} {name}"
        print(f"{calls / replies:>7.2f}  {where}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
