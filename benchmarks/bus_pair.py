"""fcmaster against a bare generic asyncio master on the same line, interleaved in one run.

Run: ``python benchmarks/bus_pair.py [--duration S] [--rounds N] [--case DRIVES,BAUD]…
[--output PATH]`` (default 3 s per run, 2 rounds, 32 and 126 drives at 19200 and 115200
baud, 5 ms response delay: about 2 minutes).

Per case one simulator process serves the drives on a pty (``benchmarks/bus.py``'s, whose
replies leave on time and which notes when it heard each request's first byte and when
each reply's last byte was due). Against it, in turn, round after round:

* **fcmaster**: the daemon's :class:`~fcmaster.bus.master.BusMaster` on the real
  :class:`~fcmaster.transport.serial.SerialTransport` and :class:`~fcmaster.clock.MonotonicClock`
  under its precise event loop, monitor-only drives with the default monitor list (every
  poll a 16-byte FC parameter telegram answered by 16 bytes), nothing else running: no
  commands, no tap, no recording clock;
* **generic**: what a user writes with the usual libraries instead: pyserial-asyncio's
  ``open_serial_connection`` (a StreamReader and StreamWriter), then for each drive in turn
  ``write``, ``await wait_for(reader.readexactly(16), timeout)`` and ``await
  asyncio.sleep(pause)``; the same 16-byte polls, no framing check, no decoding, no state.
  It runs twice: on the same precise event loop as fcmaster (``generic``) and on asyncio's
  default loop (``generic-epoll``, what ``asyncio.run`` gives it);
* **floor**: the least any asyncio master can do on this machine, for scale: a reader
  callback on the port's descriptor that counts 16 bytes and a timer that writes the next
  poll when the pause is over, on the precise loop. No framing, no checks, no state, no
  futures, no tasks: its CPU is the two wake-ups of a transaction (the reply, the end of
  the pause) and little else, and its ratio to ``generic`` is as low as fcmaster's could
  go without waking less often;
* **framed**: the floor plus the least a careful master does with each reply, for scale:
  the FC framer and its checksum, the reply parsed by the codec (or found unchanged in a
  cache, as fcmaster does), both frames logged in a ring, and a deadline timer set and
  cancelled for each request. No planner, no accounting, no reporting: what fcmaster costs
  beyond it is the price of its layers.

Figures, each over the run's window after a 0.5 s warm-up (fcmaster's: also until it has
had as many replies as the line has idle polls, see ``bus.warmed_up``, since its caches of
encoded polls and parsed replies fill once, at start), all but CPU measured by the peer
(the simulator), the same way for every master:

* **CPU s/1000**: ``time.process_time()`` of this process per 1000 replies (the simulator
  is another process);
* **efficiency**: replies per second ÷ 1 / T (T: both telegrams, the response delay and
  the FC pause of 2 characters);
* **overhead median / p99**: from a reply's last byte due on the wire to the next request's
  first byte heard, minus the pause (includes the pty both ways, the same for every master);
* **short gaps**: turnarounds the peer heard shorter than the pause (the protocol's 2
  characters), out of all it heard.

Benchmarks are not tests: nothing here passes or fails. The machine may be shared: the
load average is printed with every run, and runs of the masters alternate so a burst of
other work meets them alike.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import os
import sys
import termios
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any, Final

import bus as harness
import results_file
import serial_asyncio_fast

from fcmaster import logsetup
from fcmaster.bus.master import BusMaster
from fcmaster.clock import MonotonicClock, new_event_loop
from fcmaster.errors import UnexpectedReply
from fcmaster.protocol.codec import Reply
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.danfoss_fc.framer import FcFramer
from fcmaster.protocol.framing import Frame
from fcmaster.transport.serial import SerialTransport

DELAY_S: Final = 0.005
TIMEOUT_S: Final = 0.1  # the generic master's reply timeout
DEFAULT_OUTPUT: Final = Path(__file__).resolve().parent / "results" / "bus_pair.json"
now = time.monotonic


async def run_fcmaster(case: harness.Case, path: str, duration_s: float) -> dict[str, Any]:
    """The daemon's master polling, nothing else: replies, window and CPU."""
    plan = case.line_plan(path)
    transport = SerialTransport(path, baudrate=plan.baudrate, parity=plan.parity)
    async with BusMaster(plan, codec=FcCodec(), transport=transport, clock=MonotonicClock()) as m:
        if not m.is_up:
            raise RuntimeError(f"fcmaster could not open {path}")
        await harness.warmed_up(m)
        replies, timeouts = m.stats.replies, m.stats.timeouts
        cpu, start = time.process_time(), now()
        await asyncio.sleep(duration_s)
        end, cpu = now(), time.process_time() - cpu
        replies, timeouts = m.stats.replies - replies, m.stats.timeouts - timeouts
    return {"start": start, "end": end, "replies": replies, "timeouts": timeouts, "cpu_s": cpu}


async def run_generic(case: harness.Case, path: str, duration_s: float) -> dict[str, Any]:
    """Request, await the reply, sleep the pause: a generic asyncio serial master."""
    requests, pause = harness.poll_requests(case), case.pause_s
    reader, writer = await serial_asyncio_fast.open_serial_connection(
        url=path, baudrate=case.baudrate
    )
    counts = {"replies": 0, "timeouts": 0}

    async def cycle(until: float) -> None:
        for request in itertools.cycle(requests):
            if now() >= until:
                return
            writer.write(request)
            try:
                await asyncio.wait_for(reader.readexactly(harness.REPLY_LENGTH), TIMEOUT_S)
                counts["replies"] += 1
            except TimeoutError:
                counts["timeouts"] += 1
            await asyncio.sleep(pause)

    try:
        await cycle(now() + harness.WARMUP_S)
        counts.update(replies=0, timeouts=0)
        cpu, start = time.process_time(), now()
        await cycle(start + duration_s)
        end, cpu = now(), time.process_time() - cpu
    finally:
        writer.close()
    return {"start": start, "end": end, **counts, "cpu_s": cpu}


Later = Callable[[float, Callable[[], None]], asyncio.TimerHandle]
Callbacks = tuple[Callable[[], None], Callable[[], None]]  # the first poll's send, the reader
# Given the descriptor, the counts to keep and the way to set a timer: its callbacks.
CallbackMaster = Callable[[int, dict[str, int], Later], Callbacks]


async def on_descriptor(
    case: harness.Case, path: str, duration_s: float, master: CallbackMaster
) -> dict[str, Any]:
    """Run a callback master on the bare descriptor, measured as the others are.

    The master sets its timers with ``later``, which keeps the one it set last: a callback
    master has at most one pending (the pause's or the reply's deadline), and it is called
    off before the port closes, so nothing writes to a closed descriptor.
    """
    loop = asyncio.get_running_loop()
    port = harness.open_raw(case, path)
    fd = port.fileno()
    counts = {"replies": 0, "timeouts": 0}
    timer: asyncio.TimerHandle | None = None

    def later(delay: float, callback: Callable[[], None]) -> asyncio.TimerHandle:
        nonlocal timer
        timer = loop.call_later(delay, callback)
        return timer

    send, readable = master(fd, counts, later)
    termios.tcflush(fd, termios.TCIFLUSH)  # what the master before this one left unread
    loop.add_reader(fd, readable)
    try:
        send()
        await asyncio.sleep(harness.WARMUP_S)
        counts.update(replies=0, timeouts=0)
        cpu, start = time.process_time(), now()
        await asyncio.sleep(duration_s)
        end, cpu = now(), time.process_time() - cpu
        result = dict(counts)
    finally:
        loop.remove_reader(fd)
        if timer is not None:
            timer.cancel()
        port.close()
    return {"start": start, "end": end, **result, "cpu_s": cpu}


async def run_floor(case: harness.Case, path: str, duration_s: float) -> dict[str, Any]:
    """A reader callback and a pause timer on the bare descriptor: two wake-ups, no more."""
    requests = itertools.cycle(harness.poll_requests(case))
    pause = case.pause_s

    def floor(fd: int, counts: dict[str, int], later: Later) -> Callbacks:
        heard = 0

        def send() -> None:
            os.write(fd, next(requests))

        def readable() -> None:
            nonlocal heard
            heard += len(os.read(fd, 256))
            if heard >= harness.REPLY_LENGTH:
                heard = 0
                counts["replies"] += 1
                later(pause, send)

        return send, readable

    return await on_descriptor(case, path, duration_s, floor)


async def run_framed(case: harness.Case, path: str, duration_s: float) -> dict[str, Any]:
    """The floor, plus framing, checks, parsing through a cache, a frame log and a deadline."""
    pause = case.pause_s
    codec, framer = FcCodec(), FcFramer()
    key = codec.parameter("16-13")
    exchanges = itertools.cycle([codec.read(a, key, 0, None)[0] for a in range(1, case.drives + 1)])
    frames: deque[tuple[str, float, float, bytes]] = deque(maxlen=4096)
    parsed: dict[bytes, tuple[bytes, Reply]] = {}

    def framed(fd: int, counts: dict[str, int], later: Later) -> Callbacks:
        exchange = next(exchanges)
        deadline: asyncio.TimerHandle | None = None

        def send() -> None:
            nonlocal exchange, deadline
            exchange = next(exchanges)
            os.write(fd, exchange.request)
            frames.append(("tx", now(), time.time(), exchange.request))
            deadline = later(TIMEOUT_S, timed_out)

        def timed_out() -> None:
            counts["timeouts"] += 1
            framer.reset()
            send()

        def readable() -> None:
            at = now()
            framer.feed(os.read(fd, 256))
            piece = framer.next_frame()
            while piece is not None and not isinstance(piece, Frame):
                piece = framer.next_frame()  # skipped bytes: what an earlier master left unread
            if piece is None:
                return  # more to come
            frames.append(("rx", at, time.time(), piece.data))
            last = parsed.get(exchange.request)
            if last is None or last[0] != piece.data:
                try:
                    parsed[exchange.request] = (piece.data, codec.parse(exchange, piece.data))
                except UnexpectedReply:
                    return  # a late answer to an earlier request: wait on for this one's
            if deadline is not None:
                deadline.cancel()
            counts["replies"] += 1
            later(at + pause - now(), send)

        return send, readable

    return await on_descriptor(case, path, duration_s, framed)


MASTERS: Final[dict[str, tuple[Callable[..., Any], Callable[[], asyncio.AbstractEventLoop]]]] = {
    "fcmaster": (run_fcmaster, new_event_loop),
    "generic": (run_generic, new_event_loop),
    "generic-epoll": (run_generic, harness.LOOPS["epoll"]),
    "floor": (run_floor, new_event_loop),
    "framed": (run_framed, new_event_loop),
}


def figures(case: harness.Case, run: dict[str, Any], sim: harness.SimRecord) -> dict[str, Any]:
    """The peer-measured figures of one run."""
    t, pause = case.transaction_s, case.pause_s
    start, end = run["start"], run["end"]
    heard = [(at, reply_end) for at, reply_end in sim.transactions if start <= at <= end]
    gaps = [
        next_at - reply_end
        for (_, reply_end), (next_at, _) in itertools.pairwise(heard)
        if reply_end is not None
    ]
    overhead = [gap - pause for gap in gaps]
    replies = run["replies"] or 1
    elapsed = end - start
    return {
        "efficiency": run["replies"] / elapsed * t,
        "cpu_s_per_1000": run["cpu_s"] / replies * 1000,
        "overhead_ms": harness.spread(overhead, 1000.0),
        "short_gaps": sum(gap < pause for gap in gaps),
        "gaps": len(gaps),
        "replies": run["replies"],
        "timeouts": run["timeouts"],
        "load_average": os.getloadavg()[0],
    }


def run_case(case: harness.Case, duration_s: float, rounds: int) -> list[dict[str, Any]]:
    rows = []
    with harness.simulator(case.baudrate, case.delay_s, case.drives) as sim:
        for round_ in range(rounds):
            for name, (runner_of, factory) in MASTERS.items():
                sim.record()  # drop what came before
                with asyncio.Runner(loop_factory=factory) as runner:
                    run = runner.run(runner_of(case, sim.path, duration_s))
                row = {
                    "drives": case.drives,
                    "baudrate": case.baudrate,
                    "response_delay_ms": case.delay_s * 1000,
                    "master": name,
                    "round": round_,
                    **figures(case, run, sim.record()),
                }
                print_row(row)
                rows.append(row)
    return rows


def print_row(row: dict[str, Any]) -> None:
    ovh = row["overhead_ms"]
    print(
        f"{row['drives']:>6} {row['baudrate']:>6} {row['master']:<13} | "
        f"CPU s/1k {row['cpu_s_per_1000']:>6.3f} | eff {row['efficiency']:.3f} | ovh ms med "
        f"{ovh['median']:>6.3f} p99 {ovh['p99']:>6.3f} | short gaps {row['short_gaps']:>4} of "
        f"{row['gaps']:>5} | timeouts {row['timeouts']:>3} | load {row['load_average']:.2f}",
        flush=True,
    )


def summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per case: each master's medians over the rounds, and fcmaster's ratios to generic."""
    out = []
    cases = dict.fromkeys((r["drives"], r["baudrate"]) for r in rows)
    for drives, baudrate in cases:
        of_case = [r for r in rows if (r["drives"], r["baudrate"]) == (drives, baudrate)]
        medians = {}
        for name in MASTERS:
            mine = [r for r in of_case if r["master"] == name]
            medians[name] = {
                "cpu_s_per_1000": harness.percentile([r["cpu_s_per_1000"] for r in mine], 0.5),
                "efficiency": harness.percentile([r["efficiency"] for r in mine], 0.5),
                "overhead_median_ms": harness.percentile(
                    [r["overhead_ms"]["median"] for r in mine], 0.5
                ),
                "overhead_p99_ms": harness.percentile([r["overhead_ms"]["p99"] for r in mine], 0.5),
                "short_gaps": sum(r["short_gaps"] for r in mine),
                "gaps": sum(r["gaps"] for r in mine),
            }
        fc, generic = medians["fcmaster"], medians["generic"]
        out.append(
            {
                "drives": drives,
                "baudrate": baudrate,
                "medians": medians,
                "fcmaster_over_generic": {
                    key: fc[key] / generic[key] if generic[key] else None
                    for key in ("cpu_s_per_1000", "overhead_median_ms", "overhead_p99_ms")
                },
                **{
                    f"{name}_over_generic": {
                        key: medians[name][key] / generic[key] if generic[key] else None
                        for key in ("cpu_s_per_1000", "overhead_median_ms", "overhead_p99_ms")
                    }
                    for name in ("floor", "framed")
                },
            }
        )
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--duration", type=float, default=3.0, help="seconds per run")
    parser.add_argument("--rounds", type=int, default=2, help="runs of each master per case")
    parser.add_argument("--case", action="append", metavar="DRIVES,BAUD")
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    args = parser.parse_args(argv)
    logsetup.configure(level="warning")
    cases = [
        harness.Case(drives, baudrate, DELAY_S)
        for drives in (32, 126)
        for baudrate in (19200, 115200)
    ]
    if args.case:
        wanted = {tuple(int(v) for v in spec.split(",")) for spec in args.case}
        cases = [c for c in cases if (c.drives, c.baudrate) in wanted]
    print(
        f"FC parameter polls (16 + 16 bytes, 8E1), {DELAY_S * 1000:g} ms response delay, "
        f"{args.duration:g} s per run, {args.rounds} rounds; {os.cpu_count()} CPUs, "
        f"load {os.getloadavg()[0]:.2f}",
        flush=True,
    )
    started = now()
    rows = [row for case in cases for row in run_case(case, args.duration, args.rounds)]
    result = summary(rows)
    print("\nMedians; fcmaster, the floor and framed ÷ generic (same precise loop):")
    for entry in result:
        ratio = entry["fcmaster_over_generic"]
        parts = []
        for name, m in entry["medians"].items():
            parts.append(
                f"{name} CPU {m['cpu_s_per_1000']:.3f} eff {m['efficiency']:.3f} ovh "
                f"{m['overhead_median_ms']:.3f}/{m['overhead_p99_ms']:.3f} short "
                f"{m['short_gaps']}/{m['gaps']}"
            )
        print(f"  {entry['drives']:>3} drives {entry['baudrate']:>6}: " + "; ".join(parts))
        print(
            "      ratios: "
            + ", ".join(f"{k} {v:.2f}" if v is not None else f"{k} -" for k, v in ratio.items())
        )
        for name in ("floor", "framed"):
            print(
                f"      the {name}'s: "
                + ", ".join(
                    f"{k} {v:.2f}" if v is not None else f"{k} -"
                    for k, v in entry[f"{name}_over_generic"].items()
                )
            )
    results_file.write(
        args.output,
        {
            **results_file.provenance("bus_pair"),
            "duration_s": args.duration,
            "rounds": args.rounds,
            "wall_s": now() - started,
            "runs": rows,
            "summary": result,
        },
    )
    print(f"\nresults in {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
