"""The bus master when drives are missing, replies are lost and the port goes away.

Run: ``python benchmarks/bus_faults.py [--duration S] [--repeat N] [--output PATH]``
(about four minutes with the default 5 s windows and 3 runs of each case, interleaved;
the medians are reported, as the machine may be shared). The real BusMaster and
SerialTransport against the timed simulator in its own process, on a pty, at 115200 baud
8E1 with drives that answer after
5 ms, the least FC 8-35 allows (an FC transaction, poll and reply, is then about 8.3 ms).
Every drive is monitor-only, so every poll is a 16-byte parameter telegram.

* **poll rate with absent drives**: 16 drives answer; 0, 16 or 110 more are configured
  but absent (126 configured in the last case). After every absent drive is demoted, each
  live drive's replies per second over the window, the ratio to the case with none absent
  (target ≥ 0.9), and the longest gap between two replies of one live drive in units of
  its poll interval with none absent (target ≤ 3).
* **recovery after a line silence**: 16 drives; the simulated line goes silent for 3 s
  (every drive at once). From the end of the silence to every drive online again, in
  seconds and in poll rounds (one round: 16 transactions).
* **recovery after a port loss**: the simulator process is killed (its pty, and the link
  the master opens, vanish) and started again 1 s later on the same link. From the new
  link's appearance to the first reply, and the whole outage.
* **line rate with faults**: 16 drives; replies per second with 1 % of replies lost and
  0.5 % corrupted (1.5 % faults) against none.

Timings come from ``time.monotonic`` (one clock for both processes).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import results_file

from fcmaster import logsetup
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock, new_event_loop
from fcmaster.protocol.codec import Reply
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.drive import ControlIntent
from fcmaster.sim import DriveSettings, FaultPlan, LineSettings, PtyServer, build_line
from fcmaster.transport.serial import SerialTransport

BAUD = 115200
DELAY_S = 0.005  # the least FC 8-35 allows
PRESENT = 16
RESULTS = Path(__file__).parent / "results" / "bus_faults.json"


# -- the simulator process ---------------------------------------------------------------


async def _serve_sim(spec: dict[str, Any]) -> None:
    """Serve the line at ``spec["link"]``; print the link, then wait for stdin to close."""
    clock = MonotonicClock()
    faults = FaultPlan(
        drop=spec.get("drop", 0.0),
        corrupt=spec.get("corrupt", 0.0),
        silent_periods=tuple(tuple(p) for p in spec.get("silent", ())),  # type: ignore[misc]
        seed=1,
    )
    # Drives that lose power at a time of the line's and stay off: {"at": s, "addresses": […]}.
    loss = spec.get("power_loss")
    off = FaultPlan(silent_periods=((loss["at"], math.inf),)) if loss else None
    line = build_line(
        LineSettings(name="bench", baudrate=spec.get("baudrate", BAUD), faults=faults),
        [
            (
                a,
                DriveSettings(
                    response_delay_s=spec.get("delay_s", DELAY_S),
                    faults=off if loss and a in loss["addresses"] else None,
                ),
            )
            for a in spec.get("addresses") or range(1, spec["drives"] + 1)
        ],
        clock=clock,
    )
    loop = asyncio.get_running_loop()
    async with PtyServer(line, clock=clock, link=spec["link"]):
        print(json.dumps({"link": spec["link"], "at": time.monotonic()}), flush=True)
        await loop.run_in_executor(None, sys.stdin.read)


@contextlib.contextmanager
def simulator(**spec: Any) -> Iterator[tuple[subprocess.Popen[str], float]]:
    """The simulator in a child process; yields it and when its link appeared."""
    command = [sys.executable, os.path.abspath(__file__), "--serve-sim", json.dumps(spec)]
    process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert process.stdout is not None
    started = json.loads(process.stdout.readline())["at"]
    try:
        yield process, started
    finally:
        stop(process)


def stop(process: subprocess.Popen[str], *, kill: bool = False) -> None:
    """End the child: EOF on its stdin, or SIGKILL (a port that vanishes at once)."""
    if kill:
        process.kill()
    with contextlib.suppress(OSError):
        if process.stdin is not None:
            process.stdin.close()
    try:
        process.wait(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
    if process.stdout is not None:
        process.stdout.close()


# -- the master side ---------------------------------------------------------------------


class Replies:
    """A BusMaster observer that keeps when each drive replied."""

    def __init__(self) -> None:
        self.at: dict[str, list[float]] = {}

    def drive_replied(
        self, bus: str, drive: DrivePlan, reply: Reply, at: float, commanded: ControlIntent | None
    ) -> None:
        self.at.setdefault(drive.name, []).append(at)

    def drive_availability(self, bus: str, drive: DrivePlan, online: bool, at: float) -> None:
        pass

    def line_availability(self, bus: str, up: bool, reason: str, at: float) -> None:
        pass

    def command_completed(self, bus: str, drive: str, command: Any, result: Any) -> None:
        pass


def master_for(link: str, configured: int) -> tuple[BusMaster, Replies]:
    plan = LinePlan(
        name="bench",
        port=link,
        baudrate=BAUD,
        response_delay_s=DELAY_S,
        drives=tuple(DrivePlan(name=f"d{a}", address=a) for a in range(1, configured + 1)),
    )
    replies = Replies()
    transport = SerialTransport(link, baudrate=BAUD, parity=plan.parity)
    master = BusMaster(
        plan, codec=FcCodec(), transport=transport, clock=MonotonicClock(), observer=replies
    )
    return master, replies


async def wait_until(condition: Any, timeout_s: float) -> float:
    """Poll ``condition`` every millisecond; when it held (monotonic), or raise."""
    limit = time.monotonic() + timeout_s
    while not condition():  # the master's state signals nothing: look every millisecond
        if time.monotonic() > limit:
            raise TimeoutError("condition not met")
        await asyncio.sleep(0.001)
    return time.monotonic()


def live_rates(replies: Replies, start: float, end: float) -> tuple[float, float]:
    """Mean replies per second of a live drive in the window, and the longest gap."""
    rates, gaps = [], []
    for a in range(1, PRESENT + 1):
        times = [t for t in replies.at.get(f"d{a}", []) if start <= t <= end]
        rates.append(len(times) / (end - start))
        gaps.extend(after - before for before, after in itertools.pairwise(times))
    return sum(rates) / len(rates), max(gaps)


async def poll_rate(link: str, absent: int, duration_s: float) -> dict[str, Any]:
    with simulator(link=link, drives=PRESENT):
        master, replies = master_for(link, PRESENT + absent)
        async with master:
            slots = master.planner.slots
            await wait_until(lambda: all(s.online is (s.address <= PRESENT) for s in slots), 60)
            await asyncio.sleep(1.0)
            start = time.monotonic()
            await asyncio.sleep(duration_s)
            end = time.monotonic()
            rate, longest = live_rates(replies, start, end)
            drives = master.stats.drives
            probes = sum(d.requests for name, d in drives.items() if int(name[1:]) > PRESENT)
    return {
        "absent": absent,
        "configured": PRESENT + absent,
        "live_poll_rate_hz": rate,
        "longest_gap_s": longest,
        "probes_total": probes,
    }


async def silence_recovery(link: str) -> dict[str, Any]:
    silent_from, silent_for = 4.0, 3.0
    spec = {"link": link, "drives": PRESENT, "silent": [[silent_from, silent_from + silent_for]]}
    with simulator(**spec) as (_, started):
        master, _ = master_for(link, PRESENT)
        async with master:
            slots = master.planner.slots
            await wait_until(lambda: master.planner.line_silent, 30)
            flagged = master.planner.line_silent
            back = started + silent_from + silent_for
            recovered = await wait_until(lambda: all(s.online for s in slots), 30)
            rate = master.stats.replies
            await asyncio.sleep(1.0)
            rate = (master.stats.replies - rate) / 1.0
    return {
        "silence_s": silent_for,
        "flagged_line_silent": flagged,
        "recovery_s": recovered - back,
        "poll_round_s": PRESENT / rate,
    }


async def port_recovery(link: str) -> dict[str, Any]:
    master, replies = master_for(link, PRESENT)
    with simulator(link=link, drives=PRESENT) as (first, _):
        async with master:
            await wait_until(lambda: all(s.online for s in master.planner.slots), 30)
            lost = time.monotonic()
            stop(first, kill=True)  # the adapter is pulled out
            # and its node goes, as udev removes /dev/ttyUSB0 (a dangling link could point
            # at a pty number another process gets next)
            with contextlib.suppress(FileNotFoundError):
                os.unlink(link)
            await wait_until(lambda: not master.is_up, 10)
            await asyncio.sleep(1.0)
            count = sum(len(v) for v in replies.at.values())
            with simulator(link=link, drives=PRESENT) as (_, appeared):
                answered = await wait_until(
                    lambda: sum(len(v) for v in replies.at.values()) > count, 30
                )
    return {"reopen_after_node_appeared_s": answered - appeared, "outage_s": answered - lost}


async def fault_rate(link: str, duration_s: float, drop: float, corrupt: float) -> float:
    with simulator(link=link, drives=PRESENT, drop=drop, corrupt=corrupt):
        master, _ = master_for(link, PRESENT)
        async with master:
            await wait_until(lambda: all(s.online for s in master.planner.slots), 30)
            await asyncio.sleep(1.0)
            before, start = master.stats.replies, time.monotonic()
            await asyncio.sleep(duration_s)
            return (master.stats.replies - before) / (time.monotonic() - start)


def median(values: list[float]) -> float:
    ordered = sorted(values)
    middle = len(ordered) // 2
    return ordered[middle] if len(ordered) % 2 else (ordered[middle - 1] + ordered[middle]) / 2


async def run(duration_s: float, repeat: int) -> dict[str, Any]:
    """Each case ``repeat`` times, interleaved (the machine is shared); medians judged."""
    with tempfile.TemporaryDirectory() as tmp:
        link = os.path.join(tmp, "ttyBENCH")
        runs: dict[int, list[dict[str, Any]]] = {0: [], 16: [], 110: []}
        clean: list[float] = []
        faulty: list[float] = []
        for _ in range(repeat):
            for absent, rows in runs.items():
                rows.append(await poll_rate(link, absent, duration_s))
            clean.append(await fault_rate(link, duration_s, 0.0, 0.0))
            faulty.append(await fault_rate(link, duration_s, 0.01, 0.005))
        silence = await silence_recovery(link)
        port = await port_recovery(link)
    alone_hz = median([r["live_poll_rate_hz"] for r in runs[0]])
    rows = []
    for absent, results in runs.items():
        rate = median([r["live_poll_rate_hz"] for r in results])
        gap = median([r["longest_gap_s"] for r in results])
        rows.append(
            {
                "absent": absent,
                "configured": PRESENT + absent,
                "live_poll_rate_hz": rate,
                "rate_vs_none_absent": rate / alone_hz,
                "longest_gap_s": gap,
                "longest_gap_in_poll_intervals": gap * alone_hz,
                "runs": results,
            }
        )
    ratios = [f / c for f, c in zip(faulty, clean, strict=True)]
    return {
        "poll_rate_with_absent_drives": rows,
        "line_silence": silence,
        "port_loss": port,
        "faults": {
            "replies_per_s_clean": median(clean),
            "replies_per_s_1_5_pct_faults": median(faulty),
            "ratio": median(ratios),
            "runs_clean": clean,
            "runs_faulty": faulty,
        },
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--duration", type=float, default=5.0, help="seconds per window")
    parser.add_argument("--output", type=Path, default=RESULTS)
    parser.add_argument("--repeat", type=int, default=3, help="runs of each case (medians)")
    parser.add_argument("--serve-sim", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve_sim:
        with asyncio.Runner(loop_factory=new_event_loop) as runner:
            runner.run(_serve_sim(json.loads(args.serve_sim)))
        return 0
    logsetup.configure("error", "console")  # demotions and the lost port are expected here
    load = os.getloadavg()
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        results = runner.run(run(args.duration, args.repeat))
    results = {
        **results_file.provenance("bus_faults"),
        "loadavg_before": load,
        "loadavg_after": os.getloadavg(),
        "window_s": args.duration,
        **results,
    }
    results_file.write(args.output, results)
    for row in results["poll_rate_with_absent_drives"]:
        print(
            f"{row['absent']:>3} absent of {row['configured']:>3}: live drives "
            f"{row['live_poll_rate_hz']:6.2f} polls/s ({row['rate_vs_none_absent']:.3f} of "
            f"none absent), longest gap {row['longest_gap_in_poll_intervals']:.2f} "
            "poll intervals"
        )
    silence, port, faults = results["line_silence"], results["port_loss"], results["faults"]
    print(
        f"line silent {silence['silence_s']:.0f} s: every drive back "
        f"{silence['recovery_s'] * 1000:.0f} ms after the line answered "
        f"({silence['recovery_s'] / silence['poll_round_s']:.2f} poll rounds)"
    )
    print(
        f"port lost: first reply {port['reopen_after_node_appeared_s'] * 1000:.0f} ms after "
        f"the device node reappeared (outage {port['outage_s']:.2f} s, 1 s unplugged)"
    )
    print(
        f"1.5 % faults: {faults['replies_per_s_1_5_pct_faults']:.0f} replies/s against "
        f"{faults['replies_per_s_clean']:.0f} clean ({faults['ratio']:.3f})"
    )
    print(f"load average before {load[0]:.2f}, after {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
