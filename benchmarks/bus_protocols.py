"""Line efficiency per protocol: the real master against the timed simulator over a pty.

Run: ``python benchmarks/bus_protocols.py --protocol modbus-rtu [--baudrates 19200,115200]
[--drives 8] [--duration S] [--output PATH]``.

This is the protocol-neutral sibling of ``benchmarks/bus.py`` (which measures the FC line
in depth: overhead, command latency, CPU, epoll against the precise loop). Here one case
is a protocol at a baud rate at its factory character format, and the figure is how much
of the line the master keeps busy with useful transactions:

* The simulator runs in its own process (this script with ``--serve-sim``), as in
  ``bus.py``: :func:`~fcmaster.sim.build_line` and :class:`~fcmaster.sim.PtyServer` under
  fcmaster's precise event loop, so it never shares a loop or a GIL with the master. As
  there, its clock may wake up to ``SIM_MAX_LEAD_S`` early and spin, so its replies leave
  after exactly the drive's answer delay: with the default 0.1 ms lead, its 5 ms waits
  woke about 0.2 ms late, which the master was charged for.
* The master is the real :class:`~fcmaster.bus.master.BusMaster` on the real
  :class:`~fcmaster.transport.serial.SerialTransport`, the plan set up as the config does it
  (``codec_for``, the protocol's answer delay). Every drive is monitor-only with the
  protocol's default monitor list, so the line carries exactly the idle-poll rotation.
* **line efficiency** = transactions per second ÷ the limit 1 / T, where T is the mean,
  over one poll rotation, of request and reply on the wire (characters × bits per
  character ÷ baud), the simulated drive's answer delay for that request, and the pause the
  protocol asks after a reply (``codec.min_pause_s``). T is the line with a master that
  costs nothing; the shortfall is the master's overhead, the pty and the machine's load.

Per protocol (:data:`PROTOCOLS`): the factory character format, the stations to use and the
simulated drive's answer delay. Another protocol is one more entry there.

Benchmarks are not tests: nothing here passes or fails.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import os
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import results_file

from fcmaster import logsetup
from fcmaster.bus.codecs import codec_for, with_protocol_delay
from fcmaster.bus.frame_log import RX, TX, FrameRecord
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock, new_event_loop
from fcmaster.protocol.codec import DriveCodec, Exchange
from fcmaster.sim import DriveSettings, LineSettings, PtyServer, build_line
from fcmaster.sim.mitsubishi.drive import DEFAULT_CHECK_S
from fcmaster.sim.modbus_rtu import profile_for
from fcmaster.transport.serial import SerialTransport

WARMUP_S: Final = 0.5
SIM_MAX_LEAD_S: Final = 0.001  # as bus.py: the simulator may spin up to 1 ms to be on time
DEFAULT_OUTPUT: Final = Path(__file__).resolve().parent / "results" / "bus_protocols.json"


@dataclass(slots=True, frozen=True)
class Protocol:
    """What a case of one protocol needs."""

    parity: str
    stopbits: int
    first_address: int
    # the simulated drive's delay from the end of a request to its reply
    answer_s: Callable[[Exchange], float]
    drive: DriveSettings = field(default_factory=DriveSettings)  # every simulated drive
    # the profile of the drive at an address, for protocols whose drives follow one
    profile_of: Callable[[int], object] | None = None


PROTOCOLS: Final[dict[str, Protocol]] = {
    # Factory 8E2 (Pr.119 = 1, Pr.120 = 2); the waiting-time digit 0 travels; the drive
    # checks a monitor request in DEFAULT_CHECK_S (the manual allows up to 12 ms).
    "mitsubishi": Protocol("E", 2, 0, lambda exchange: DEFAULT_CHECK_S),  # stations 0-31
    # Factory 8N1 (F2.14 = 03), every drive answering 5 ms after a request.
    "enc": Protocol("N", 1, 1, lambda exchange: 0.005, DriveSettings(response_delay_s=0.005)),
    # Factory 8E1 (Serial Line §2.5.1), every drive answering 2 ms after a request; the
    # simulated drives follow the built-in profiles in turn by address, and so does the plan.
    "modbus-rtu": Protocol(
        "E",
        1,
        1,
        lambda exchange: 0.002,
        DriveSettings(response_delay_s=0.002),
        profile_of=lambda address: profile_for(address, DriveSettings()),
    ),
}


@dataclass(slots=True, frozen=True)
class Case:
    """One protocol at one baud rate with ``drives`` monitor-only drives."""

    protocol: str
    baudrate: int
    drives: int

    @property
    def spec(self) -> Protocol:
        """The protocol's entry in :data:`PROTOCOLS`."""
        return PROTOCOLS[self.protocol]

    def plan(self, port: str) -> LinePlan:
        """The master's plan, as the config would make it."""
        first = self.spec.first_address
        plan = LinePlan(
            name="bench", port=port, protocol=self.protocol, baudrate=self.baudrate,
            parity=self.spec.parity, stopbits=self.spec.stopbits,
            drives=tuple(DrivePlan(name=f"d{a}", address=a, profile=self.profile(a))
                         for a in range(first, first + self.drives)),
        )  # fmt: skip
        return with_protocol_delay(plan)

    def profile(self, address: int) -> object:
        """The drive profile of the drive at ``address`` (None: the protocol has none)."""
        return None if self.spec.profile_of is None else self.spec.profile_of(address)

    def transaction_s(self) -> float:
        """T: the mean ideal time of one idle poll over the rotation (module docstring).

        Over every drive's rotation: on a Modbus line each drive polls as its profile says.
        """
        plan = self.plan("")
        codec: DriveCodec = codec_for(plan)
        times = []
        for drive in plan.drives:
            monitor = codec.default_monitor() if drive.monitor is None else drive.monitor
            keys = tuple(codec.parameter(m) if isinstance(m, str) else m for m in monitor)
            for read in codec.poll_sequence(keys):
                exchange = codec.poll(drive.address, None, read)
                wire = plan.wire_s(len(exchange.request) + exchange.reply_length)
                pause = codec.min_pause_s(plan.char_s)
                times.append(wire + self.spec.answer_s(exchange) + pause)
        return sum(times) / len(times)


# -- the simulator process ---------------------------------------------------------------


async def _serve_sim(case: Case) -> None:
    """Serve the case's line on a pty; print its path; run until stdin closes."""
    clock = MonotonicClock(max_lead_s=SIM_MAX_LEAD_S)
    first = case.spec.first_address
    line = build_line(
        LineSettings(name="bench", protocol=case.protocol, baudrate=case.baudrate,
                     parity=case.spec.parity, stopbits=case.spec.stopbits),
        [(a, case.spec.drive) for a in range(first, first + case.drives)],
        clock=clock,
    )  # fmt: skip
    loop = asyncio.get_running_loop()
    async with PtyServer(line, clock=clock) as server:
        print(server.device, flush=True)
        while await loop.run_in_executor(None, sys.stdin.readline):
            pass


@contextlib.contextmanager
def simulator(case: Case) -> Iterator[str]:
    """A simulator process for the block; its pty path."""
    spec = f"{case.protocol},{case.baudrate},{case.drives}"
    process = subprocess.Popen(
        [sys.executable, os.path.abspath(__file__), "--serve-sim", spec],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert process.stdin is not None
    assert process.stdout is not None
    try:
        path = process.stdout.readline().strip()
        if not path:
            raise RuntimeError(f"the simulator did not start ({spec})")
        yield path
    finally:
        process.stdin.close()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        process.stdout.close()


# -- the master side -------------------------------------------------------------------


async def run_case(case: Case, path: str, duration_s: float) -> dict[str, Any]:
    """Poll for ``duration_s`` after a warm-up; the case's figures."""
    plan = case.plan(path)
    transport = SerialTransport(
        path, baudrate=plan.baudrate, parity=plan.parity, stopbits=plan.stopbits
    )
    clock = MonotonicClock()
    async with BusMaster(plan, codec=codec_for(plan), transport=transport, clock=clock) as master:
        if not master.is_up:
            raise RuntimeError(f"the master could not open {path}")
        await asyncio.sleep(WARMUP_S)
        stats = master.stats
        replies, timeouts, start = stats.replies, stats.timeouts, clock.now()
        frames, seq = [], master.frames.since().next
        while clock.now() - start < duration_s:
            await asyncio.sleep(0.1)  # the frame log holds the last frames only: read often
            taken = master.frames.since(seq)
            frames += taken.frames
            seq = taken.next
        elapsed = clock.now() - start
        replies, timeouts = stats.replies - replies, stats.timeouts - timeouts
    pauses = _pauses(frames)
    shortest = codec_for(plan).min_pause_s(plan.char_s)
    transaction_s = case.transaction_s()
    per_s = replies / elapsed
    return {
        "protocol": case.protocol,
        "baudrate": case.baudrate,
        "format": f"8{case.spec.parity}{case.spec.stopbits}",
        "drives": case.drives,
        "transactions_per_s": round(per_s, 2),
        "ideal_transaction_ms": round(transaction_s * 1000, 3),
        "efficiency": round(per_s * transaction_s, 4),
        "timeouts": timeouts,
        # from a reply's arrival to the next request's write, as the master's frame log has it
        "pause_min_ms": round(min(pauses) * 1000, 3) if pauses else None,
        "pause_median_ms": round(sorted(pauses)[len(pauses) // 2] * 1000, 3) if pauses else None,
        "protocol_pause_ms": round(shortest * 1000, 3),
        "requests_sooner_than_the_pause": sum(p < shortest for p in pauses),
        "seconds": round(elapsed, 2),
        "load_average": os.getloadavg()[0],
    }


def _pauses(frames: list[FrameRecord]) -> list[float]:
    """Each time from a received frame to the request written next."""
    return [
        after[2] - before[2]
        for before, after in itertools.pairwise(frames)
        if before[1] == RX and after[1] == TX
    ]


def main(argv: list[str] | None = None) -> int:
    """Run the cases; print a table; write the JSON results."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--protocol", choices=sorted(PROTOCOLS), default="mitsubishi")
    parser.add_argument("--baudrates", default="9600,19200")
    parser.add_argument("--drives", type=int, default=8)
    parser.add_argument("--duration", type=float, default=10.0, help="seconds per case")
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    parser.add_argument("--serve-sim", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve_sim:
        protocol, baudrate, drives = args.serve_sim.split(",")
        with asyncio.Runner(loop_factory=new_event_loop) as runner:
            runner.run(_serve_sim(Case(protocol, int(baudrate), int(drives))))
        return 0
    logsetup.configure(level="warning", fmt="json")
    rows = []
    for baudrate in (int(b) for b in args.baudrates.split(",")):
        case = Case(args.protocol, baudrate, args.drives)
        with simulator(case) as path, asyncio.Runner(loop_factory=new_event_loop) as runner:
            row = runner.run(run_case(case, path, args.duration))
        rows.append(row)
        print(
            f"{row['protocol']:<11} {row['baudrate']:>6} {row['format']}  "
            f"{row['transactions_per_s']:>7.2f}/s  T={row['ideal_transaction_ms']:.2f} ms  "
            f"efficiency {row['efficiency']:.3f}  timeouts {row['timeouts']}  "
            f"pause min {row['pause_min_ms']} ms (protocol {row['protocol_pause_ms']} ms, "
            f"{row['requests_sooner_than_the_pause']} sooner)  "
            f"load {row['load_average']:.2f}",
            flush=True,
        )
    args.output.parent.mkdir(parents=True, exist_ok=True)
    results_file.write(args.output, {**results_file.provenance("bus_protocols"), "cases": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
