"""A line's start with most of its drives absent: do the present ones keep their poll rate?

Run: ``python benchmarks/startup_absent.py [--seconds S] [--output PATH] [--label L]``
(about seven minutes with the default 40 s and 3 runs of each case, interleaved; the
medians are reported, as the machine may be shared). The real BusMaster and SerialTransport against
the timed simulator in its own process (``bus_faults.py``'s), on a pty at 115200 baud 8E1,
drives answering after 5 ms. 126 drives are configured, every one ``control: bus`` with
``on_start: adopt``; 16 are present: addresses 1–16, or (the ``spread`` cases) 1 and
112–126, behind 110 absent ones. Measured from the moment the master starts, as after a
gateway restart:

* **rate**: the present drives' answered polls per second in the windows 3–20 s and
  20–40 s, as a ratio to the same drives' rate with only them configured (all alive);
* **longest gap**: per present drive, the longest time from the start, or from an answered
  request, to its next answered request (the issue's target: max(0.5 s, 3 poll intervals));
* **first valid control word**: per present drive, the time from the start until the first
  request to it whose control word is marked valid (FC bit 10), so the drive's own
  control-word timeout is fed again — taken from the bytes written to the port.

Five cases: all alive (16 configured); 126 configured with a user's ``timeout_s: 0.1`` and
``retries: 1``; 126 configured with the default timeouts; and the spread layout with the
user's timeouts, at a first start (nothing known) and at a restart, where the record of the
drives answering when the daemon last ran (``fcmaster.presence``) names the 16 present ones.
Timings come from ``time.monotonic``.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import results_file
from bus_faults import BAUD, DELAY_S, PRESENT, Replies, simulator

import fcmaster
from fcmaster import logsetup
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock, new_event_loop
from fcmaster.protocol.danfoss_fc import ControlWord, decode_telegram
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.transport.serial import SerialTransport

CONFIGURED = 126
WINDOWS = ((3.0, 20.0), (20.0, 40.0))
RESULTS = Path(__file__).parent / "results" / "startup_absent.json"


class WrittenTransport(SerialTransport):
    """The serial port, keeping when each request was written and its bytes."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.written: list[tuple[float, bytes]] = []

    async def write(self, data: bytes) -> None:
        self.written.append((time.monotonic(), data))
        await super().write(data)

    def write_now(self, data: bytes) -> None:
        self.written.append((time.monotonic(), data))
        super().write_now(data)


def window_name(window: tuple[float, float]) -> str:
    """ "3-20s" for the window from 3 to 20 s after the start."""
    return f"{window[0]:g}-{window[1]:g}s"


async def run_case(
    link: str,
    configured: int,
    seconds: float,
    present: tuple[int, ...],
    answered_before: frozenset[int],
    **timing: Any,
) -> dict[str, Any]:
    """Start a master on ``link`` with ``configured`` drives; what the ``present`` ones got."""
    plan = LinePlan(
        name="bench",
        port=link,
        baudrate=BAUD,
        response_delay_s=DELAY_S,
        drives=tuple(
            DrivePlan(name=f"d{a}", address=a, control=True) for a in range(1, configured + 1)
        ),
        **timing,
    )
    replies = Replies()
    transport = WrittenTransport(link, baudrate=BAUD, parity=plan.parity)
    master = BusMaster(
        plan,
        codec=FcCodec(),
        transport=transport,
        clock=MonotonicClock(),
        observer=replies,
        answered_before=answered_before,
    )
    start = time.monotonic()
    async with master:
        await asyncio.sleep(seconds - (time.monotonic() - start))
    end = start + seconds
    valid: dict[int, float] = {}
    for at, data in transport.written:
        telegram = decode_telegram(data, from_drive=False)
        if telegram.pcd1 & ControlWord.DATA_VALID and telegram.address not in valid:
            valid[telegram.address] = at - start
    absent_s = dict.fromkeys(WINDOWS, 0.0)  # line time taken by requests to absent drives
    for (at, data), (after, _) in itertools.pairwise(transport.written):
        if decode_telegram(data, from_drive=False).address not in present:
            for low, high in WINDOWS:
                if low <= at - start < high:
                    absent_s[(low, high)] += after - at
    gaps: list[float] = []
    counts: dict[tuple[float, float], list[int]] = {w: [] for w in WINDOWS}
    for a in present:
        times = [t for t in replies.at.get(f"d{a}", []) if t <= end]
        gaps.append(max(b - a_ for a_, b in itertools.pairwise([start, *times, end])))
        for low, high in WINDOWS:
            counts[(low, high)].append(sum(1 for t in times if low <= t - start < high))
    return {
        "configured": configured,
        **timing,
        "replies_per_drive": {window_name(w): statistics.mean(counts[w]) for w in WINDOWS},
        "absent_line_share": {window_name(w): absent_s[w] / (w[1] - w[0]) for w in WINDOWS},
        "longest_gap_s": {"max": max(gaps), "median": statistics.median(gaps)},
        "first_valid_control_word_s": {
            "max": max(valid.get(a, math.inf) for a in present),
            "median": statistics.median(valid.get(a, math.inf) for a in present),
            "missing": [a for a in present if a not in valid],
        },
        "requests": master.stats.requests,
        "timeouts": master.stats.timeouts,
    }


LOW = tuple(range(1, PRESENT + 1))
SPREAD = (1, *range(CONFIGURED - PRESENT + 2, CONFIGURED + 1))  # 1 and 112-126
USER = {"timeout_s": 0.1, "retries": 1}
# name, drives configured, drives present, what the record says answered before, timeouts
CASES: tuple[tuple[str, int, tuple[int, ...], frozenset[int], dict[str, Any]], ...] = (
    ("all_alive", PRESENT, LOW, frozenset(), USER),
    ("absent_user_timeouts", CONFIGURED, LOW, frozenset(), USER),
    ("absent_default_timeouts", CONFIGURED, LOW, frozenset(), {}),
    ("spread_first_start", CONFIGURED, SPREAD, frozenset(), USER),
    ("spread_restart", CONFIGURED, SPREAD, frozenset(SPREAD), USER),
)


async def measure(seconds: float, repeat: int) -> dict[str, Any]:
    """Every case ``repeat`` times, interleaved (the machine may be shared); their medians.

    Each run's rate is compared with the all-alive run of the same round.
    """
    link = os.path.join(tempfile.mkdtemp(prefix="fcm-startup-"), "tty")
    runs: dict[str, list[dict[str, Any]]] = {name: [] for name, *_ in CASES}
    for _ in range(repeat):
        for name, configured, present, before, timing in CASES:
            with simulator(link=link, drives=PRESENT, addresses=present):
                run = await run_case(link, configured, seconds, present, before, **timing)
                runs[name].append(run)
        alive = runs["all_alive"][-1]["replies_per_drive"]
        poll_interval_s = (WINDOWS[1][1] - WINDOWS[1][0]) / alive[window_name(WINDOWS[1])]
        for name, *_ in CASES:
            run = runs[name][-1]
            run["rate_vs_all_alive"] = {w: run["replies_per_drive"][w] / alive[w] for w in alive}
            run["gap_target_s"] = max(0.5, 3 * poll_interval_s)
    return {name: {**_medians(case_runs), "runs": case_runs} for name, case_runs in runs.items()}


def _medians(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The median of each figure over ``runs`` (nested dicts alike; lists are kept whole)."""
    first = runs[0]
    out: dict[str, Any] = {}
    for key, value in first.items():
        if isinstance(value, dict):
            out[key] = _medians([run[key] for run in runs])
        elif isinstance(value, int | float) and not isinstance(value, bool):
            out[key] = statistics.median(run[key] for run in runs)
        elif isinstance(value, list):
            out[key] = sorted({item for run in runs for item in run[key]})
        else:
            out[key] = value
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=40.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--output", type=Path, default=RESULTS)
    parser.add_argument("--label", default="", help="what code this is (e.g. before)")
    args = parser.parse_args(argv)
    logsetup.configure("error", "console")  # absent drives going offline are expected here
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        cases = runner.run(measure(args.seconds, args.repeat))
    results = {
        **results_file.provenance("startup_absent"),
        "label": args.label,
        "fcmaster_imported_from": str(Path(fcmaster.__file__).resolve().parent),
        "loadavg": os.getloadavg(),
        "baudrate": BAUD,
        "present": PRESENT,
        "seconds": args.seconds,
        "repeat": args.repeat,
        "cases": cases,
    }
    results_file.write(args.output, results)
    summary = {name: {k: v for k, v in case.items() if k != "runs"} for name, case in cases.items()}
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
