"""Most of a running line loses power at once: how long do the drives still on wait?

Run: ``python benchmarks/mass_loss.py [--seconds S] [--repeat N] [--output PATH]`` (about
seven minutes with the default 100 s and one run of each case).

A cabinet's supply switched off, a feeder tripped, an electrician at work: 110 of a line's
126 drives stop answering together while the master polls them all. The 16 drives still
on (addresses 1–16) need their polls, and their control words, within their control-word
watchdog's time (8-03; 5 s is common), or their motors stop. The real BusMaster and
SerialTransport against the timed simulator in its own process (``bus_faults.py``'s), on a
pty, 8E1, drives answering after FC's default minimum response delay (8-35 = 10 ms); every
drive ``control: bus``. The power goes at 10 s (the line's clock), after every drive was
found; the run goes on until ``--seconds``.

Four cases: 19200 and 115200 baud, each with the default timeouts (the deadline follows the
answer times measured) and with a user's ``timeout_s: 0.1, retries: 1``. Figures, measured
from the replies the master took (the observer's times) over the loss and after it:

* **longest gap**: the longest time one of the 16 drives went without an answered request;
* **gaps over 2 s / 5 s**: how many times one of them went that long (each drive counted);
* **all given up**: when the last of the 110 was reported offline, seconds after the loss.

Benchmarks are not tests: nothing here passes or fails.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import results_file
from bus_faults import Replies, simulator

from fcmaster import logsetup
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock, new_event_loop
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.transport.serial import SerialTransport

CONFIGURED = 126
ON = tuple(range(1, 17))  # the drives that keep their power
LOST = tuple(range(17, CONFIGURED + 1))
LOSS_AT_S = 10.0  # the line's clock
DELAY_S = 0.010  # FC 8-35's default
USER = {"timeout_s": 0.1, "retries": 1}
RESULTS = Path(__file__).parent / "results" / "mass_loss.json"


class Watched(Replies):
    """Replies, and when each drive was reported offline."""

    def __init__(self) -> None:
        super().__init__()
        self.offline_at: dict[str, float] = {}

    def drive_availability(self, bus: str, drive: DrivePlan, online: bool, at: float) -> None:
        if not online:
            self.offline_at[drive.name] = at


async def run_case(link: str, baudrate: int, seconds: float, **timing: Any) -> dict[str, Any]:
    """One run: the master on ``link`` until ``seconds`` after the line started."""
    spec = {
        "link": link,
        "drives": CONFIGURED,
        "baudrate": baudrate,
        "delay_s": DELAY_S,
        "power_loss": {"at": LOSS_AT_S, "addresses": LOST},
    }
    with simulator(**spec) as (_, line_started):
        plan = LinePlan(
            name="bench",
            port=link,
            baudrate=baudrate,
            response_delay_s=DELAY_S,
            drives=tuple(DrivePlan(name=f"d{a}", address=a, control=True) for a in ON + LOST),
            **timing,
        )
        watched = Watched()
        transport = SerialTransport(link, baudrate=baudrate, parity=plan.parity)
        master = BusMaster(
            plan, codec=FcCodec(), transport=transport, clock=MonotonicClock(), observer=watched
        )
        async with master:
            await asyncio.sleep(line_started + seconds - time.monotonic())
    lost_at, end = line_started + LOSS_AT_S, line_started + seconds
    gaps: list[float] = []
    for a in ON:
        times = [t for t in watched.at.get(f"d{a}", []) if lost_at - 1.0 <= t <= end]
        gaps += [b - a_ for a_, b in itertools.pairwise([*times, end])]
    offline = [watched.offline_at.get(f"d{a}") for a in LOST]
    missing = sum(at is None for at in offline)
    return {
        "baudrate": baudrate,
        **timing,
        "longest_gap_s": max(gaps),
        "gaps_over_2s": sum(g > 2.0 for g in gaps),
        "gaps_over_5s": sum(g > 5.0 for g in gaps),
        "all_given_up_s": None if missing else max(at for at in offline if at) - lost_at,
        "still_online": missing,
        "falsely_offline": sorted(n for n in watched.offline_at if int(n[1:]) in ON),
    }


CASES = (
    ("19200_default", 19200, {}),
    ("19200_user", 19200, USER),
    ("115200_default", 115200, {}),
    ("115200_user", 115200, USER),
)


async def measure(seconds: float, repeat: int) -> dict[str, Any]:
    link = os.path.join(tempfile.mkdtemp(prefix="fcm-loss-"), "tty")
    runs: dict[str, list[dict[str, Any]]] = {name: [] for name, *_ in CASES}
    for _ in range(repeat):
        for name, baudrate, timing in CASES:
            run = await run_case(link, baudrate, seconds, **timing)
            print(name, json.dumps(run), flush=True)
            runs[name].append(run)
    return {
        name: {
            "longest_gap_s": statistics.median(r["longest_gap_s"] for r in case),
            "runs": case,
        }
        for name, case in runs.items()
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=100.0)
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    logsetup.configure("error", "console")  # 110 drives going offline are expected here
    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        cases = runner.run(measure(args.seconds, args.repeat))
    results_file.write(
        args.output,
        {
            **results_file.provenance("mass_loss"),
            "loadavg": os.getloadavg(),
            "configured": CONFIGURED,
            "on": len(ON),
            "loss_at_s": LOSS_AT_S,
            "response_delay_s": DELAY_S,
            "seconds": args.seconds,
            "cases": cases,
        },
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
