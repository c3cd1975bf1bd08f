"""What keeping a line's frames for captures costs the bus: one FrameLog.add per frame.

Run: ``python benchmarks/frame_log.py [--iterations N] [--repeats R]``. Prints the median
over ``repeats`` runs of the cost of one ``add`` (a tuple appended to a full ring, with a
sequence number and the wall-clock time), in nanoseconds, and its share of the shortest
transaction the bus makes (two 16-byte FC telegrams at 115200 baud, ~3 ms: two adds).
"""

from __future__ import annotations

import argparse
import statistics
import time

from fcmaster.bus.frame_log import FRAME_LOG_LENGTH, TX, FrameLog
from fcmaster.clock import MonotonicClock

TRANSACTION_S = 32 * 11 / 115200  # request and reply, 16 bytes each, 8E1


def one_run(iterations: int) -> float:
    log = FrameLog(MonotonicClock().wall)
    data = bytes(16)
    for _ in range(FRAME_LOG_LENGTH):  # a full ring: every add also drops the oldest
        log.add(TX, data, 0.0)
    started = time.perf_counter()
    for n in range(iterations):
        log.add(TX, data, float(n))
    return (time.perf_counter() - started) / iterations


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--iterations", type=int, default=200_000)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    per_add = statistics.median(one_run(args.iterations) for _ in range(args.repeats))
    with open("/proc/loadavg") as loadavg:
        load = loadavg.read().split()[0]
    share = 2 * per_add / TRANSACTION_S
    print(
        f"FrameLog.add: {per_add * 1e9:.0f} ns per frame; two per transaction are "
        f"{share:.4%} of a {TRANSACTION_S * 1e3:.2f} ms transaction (load {load})"
    )


if __name__ == "__main__":
    main()
