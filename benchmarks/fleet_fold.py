"""What one reply costs the fleet state and the hub, for an unchanged and a changing reply.

Run: ``python benchmarks/fleet_fold.py [--replies 50000]``.

A FleetState publishing to a Hub with one open subscription (as with one dashboard open)
folds FC poll replies for one drive: status, output and one monitored value, as the idle
poll brings them, rotating through the FC default monitor list (seven parameters).
**unchanged**: each parameter reads the same every time (a steady drive); **changing**:
the value read moves every reply. Reported: microseconds per reply (the
bus's observer call, which runs between two transactions) and how many updates the
subscription was handed. The subscription is drained after each reply, so conflation
does not hide the hub's work. Single-threaded, ``time.perf_counter``.
"""

from __future__ import annotations

import argparse
import json
import os
import time

from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock
from fcmaster.hub import Hub
from fcmaster.protocol.codec import DriveStatus, ParameterKey, ParameterValue, Reply
from fcmaster.state import FleetState

DRIVE = DrivePlan(name="pump-1", address=1, nominal_frequency_hz=50.0)
LINE = LinePlan(name="line1", port="sim://line1", drives=(DRIVE,))
STATUS = DriveStatus(word=0x0F07, running=True, fault=False, warning=False, at_reference=True)
MONITOR = [ParameterKey(f"16-{n:02d}", 1600 + n) for n in (13, 14, 12, 10, 30, 90, 92)]


def _reply(n: int, amount: float) -> Reply:
    key = MONITOR[n % len(MONITOR)]
    value = ParameterValue(parameter=key, index=0, raw=int(amount * 100), value=amount, unit="")
    return Reply(address=1, status=STATUS, output_frequency_hz=42.0, value=value)


def measure(replies: int, *, changing: bool) -> dict[str, float]:
    """Fold ``replies`` replies; µs per reply and updates delivered."""
    clock = MonotonicClock()
    hub = Hub()
    fleet = FleetState((LINE,), emit=hub.publish, clock=clock)
    subscription = hub.subscribe()
    prepared = [_reply(n, 5.0 + (n // 7 % 2) * 0.5 if changing else 5.0) for n in range(replies)]
    delivered = 0
    started = time.perf_counter()
    for reply in prepared:
        fleet.drive_replied("line1", DRIVE, reply, clock.now(), None)
        while subscription.get_nowait() is not None:
            delivered += 1
    elapsed = time.perf_counter() - started
    return {"us_per_reply": elapsed / replies * 1e6, "updates_delivered": delivered}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--replies", type=int, default=50_000)
    args = parser.parse_args()
    results = {
        "load_average": os.getloadavg(),
        "unchanged": min(
            (measure(args.replies, changing=False) for _ in range(3)),
            key=lambda r: r["us_per_reply"],
        ),
        "changing": min(
            (measure(args.replies, changing=True) for _ in range(3)),
            key=lambda r: r["us_per_reply"],
        ),
    }
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
