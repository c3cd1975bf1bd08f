"""What the HTTP adapter costs the event loop it shares with the lines.

Run: ``python benchmarks/http_render.py [--drives 126] [--lines 1]``.

A fleet of ``--drives`` FC drives (each with the default seven monitored values, some with
an active alarm or warning) spread over ``--lines`` lines with realistic statistics is built
from real parts (FleetState, LineStats), then timed, in-process and without sockets:

* ``/metrics``: one whole Prometheus exposition (:func:`fcmaster.adapters.metrics.render`);
* ``/api/v1/drives``: every drive state to strict JSON, as the handler answers it;
* one stream message: a ``drive`` event serialised for one WebSocket client;
* ``reply fold+publish``: the bus's side — one reply folded into the fleet state and
  published to a hub with 10 stream subscriptions (what a slow client can cost the bus).

Figures are the median of ``--repeat`` runs, in milliseconds or microseconds.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

from fcmaster.adapters.gateway import LineInfo
from fcmaster.adapters.messages import event_json
from fcmaster.adapters.metrics import YIELD_EVERY, render
from fcmaster.adapters.middleware import strict_json
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.bus.stats import DriveStats, LineStats
from fcmaster.clock import MonotonicClock
from fcmaster.hub import Hub
from fcmaster.protocol.codec import (
    Condition,
    ConditionReport,
    DriveStatus,
    ParameterKey,
    ParameterValue,
    Reply,
)
from fcmaster.protocol.drive import ControlIntent
from fcmaster.state import DriveUpdated, FleetState

VALUES = (
    ("16-13", "Hz"),
    ("16-14", "A"),
    ("16-12", "V"),
    ("16-10", "kW"),
    ("16-30", "V"),
    ("16-90", ""),
    ("16-92", ""),
)


def _fleet(drives: int, lines: int) -> tuple[FleetState, list[LineInfo], Hub]:
    clock = MonotonicClock()
    hub = Hub()
    per_line = -(-drives // lines)
    plans = tuple(
        LinePlan(
            name=f"line{n + 1}",
            port=f"/dev/ttyUSB{n}",
            baudrate=115200,
            drives=tuple(
                DrivePlan(name=f"drive-{n + 1}-{a}", address=a, control=a % 2 == 0)
                for a in range(1, min(per_line, drives - n * per_line) + 1)
            ),
        )
        for n in range(lines)
    )
    fleet = FleetState(plans, emit=hub.publish, clock=clock)
    infos = []
    for plan in plans:
        stats = LineStats(up_since=clock.now() - 3600, requests=10**6, replies=10**6 - 40)
        for drive in plan.drives:
            stats.drives[drive.name] = DriveStats(requests=8000, replies=7999, last_latency_s=0.005)
            for step, (param, unit) in enumerate(VALUES):
                status = DriveStatus(
                    word=0x0F07, running=True, fault=False, warning=False, at_reference=True
                )
                value = ParameterValue(
                    parameter=ParameterKey(param, 0), index=0, raw=step, value=step * 1.5, unit=unit
                )
                reply = Reply(
                    address=drive.address, status=status, output_frequency_hz=48.2, value=value
                )
                fleet.drive_replied(plan.name, drive, reply, clock.now(), ControlIntent())
            if drive.address % 10 == 0:
                report = ConditionReport(
                    kind="alarm", source="16-90", active=(Condition(14, "Earth fault"),)
                )
                fleet.drive_replied(
                    plan.name,
                    drive,
                    Reply(address=drive.address, conditions=report),
                    clock.now(),
                    None,
                )
        for n in range(5000):
            stats.latency.observe(0.004 + (n % 7) * 0.001)
            stats.turnaround.observe(0.0002 + (n % 5) * 0.0001)
        infos.append(
            LineInfo(
                name=plan.name,
                port=plan.port,
                protocol=plan.protocol,
                baudrate=plan.baudrate,
                up=True,
                drives=tuple(d.name for d in plan.drives),
                stats=stats.to_json(clock.now()),
            )
        )
    return fleet, infos, hub


def _median_s(work: Callable[[], object], repeat: int, inner: int = 1) -> float:
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        for _ in range(inner):
            work()
        times.append((time.perf_counter() - started) / inner)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drives", type=int, default=126)
    parser.add_argument("--lines", type=int, default=1)
    parser.add_argument("--repeat", type=int, default=50)
    args = parser.parse_args()
    fleet, lines, hub = _fleet(args.drives, args.lines)
    text = render(fleet.snapshot(), lines, hub)
    body = strict_json([s.to_json() for s in fleet.snapshot()])
    state = fleet.snapshot()[0]
    message = strict_json(event_json(DriveUpdated(state)))

    metrics_s = _median_s(lambda: render(fleet.snapshot(), lines, hub), args.repeat)
    drives_s = _median_s(lambda: strict_json([s.to_json() for s in fleet.snapshot()]), args.repeat)
    event_s = _median_s(
        lambda: strict_json(event_json(DriveUpdated(state))), args.repeat, inner=200
    )
    slice_s = metrics_s * YIELD_EVERY / max(1, args.drives)
    subscriptions = [hub.subscribe() for _ in range(10)]
    line_name, plan = lines[0].name, fleet.snapshot()[0]
    drive_plan = DrivePlan(name=plan.name, address=plan.address, control=False)
    status = DriveStatus(word=0x0F07, running=True, fault=False, warning=False, at_reference=True)
    reply = Reply(address=plan.address, status=status, output_frequency_hz=48.0)
    clock = MonotonicClock()
    fold_s = _median_s(
        lambda: fleet.drive_replied(line_name, drive_plan, reply, clock.now(), None),
        args.repeat,
        inner=200,
    )
    pending = max(s.pending for s in subscriptions)
    print(f"fleet: {args.drives} drives on {args.lines} line(s)")
    print(
        f"/metrics           {metrics_s * 1000:7.2f} ms   {len(text) / 1024:6.1f} KiB, "
        f"{text.count(chr(10))} lines"
    )
    print(f"  served in slices of {YIELD_EVERY} drives: about {slice_s * 1000:.2f} ms each")
    print(f"/api/v1/drives     {drives_s * 1000:7.2f} ms   {len(body) / 1024:6.1f} KiB")
    print(
        f"  served in slices of 16 drives: about {drives_s * 16 / args.drives * 1000:.2f} ms each"
    )
    print(f"stream message     {event_s * 1e6:7.1f} µs   {len(message)} bytes per drive event")
    print(f"reply fold+publish {fold_s * 1e6:7.1f} µs   (10 subscriptions; {pending} pending max)")


if __name__ == "__main__":
    main()
