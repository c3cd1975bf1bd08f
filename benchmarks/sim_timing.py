"""How closely a simulated transaction takes the time of the real wire.

Run: ``python benchmarks/sim_timing.py [--count 300] [--bauds 9600,19200,115200]``.

For each baud rate one FC parameter poll (16 bytes each way, 8E1, 10 ms response delay)
is repeated back to back, and its duration compared with the theoretical wire time
(request + response delay + reply):

* ``pty``: ``fcmaster sim`` in its own process on a pseudo-terminal, and a plain pyserial
  client here, timing from its ``write`` to the last reply byte it reads. This includes
  the pty's and both processes' wake-up latency.
* ``in-process``: :class:`~fcmaster.sim.SimTransport` on the real clock under the
  precise event loop (:func:`fcmaster.clock.new_event_loop`), timing with the line's own
  transaction records: from the request's arrival to the moment ``read`` returned it, and
  the gap from a reply's delivery to the next request's arrival (the client's overhead).

A ratio of 1.000 is the wire exactly; the simulator never goes below it.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time

import serial

from fcmaster.clock import MonotonicClock, new_event_loop
from fcmaster.protocol.danfoss_fc import FcFramer, Telegram, encode_telegram, make_pke
from fcmaster.protocol.framing import Frame
from fcmaster.sim import DriveSettings, LineSettings, SimTransport, build_line

DELAY_S = 0.010
REQUEST = encode_telegram(Telegram(address=1, pcd1=0x047C, pcd2=0x2000, pke=make_pke(1, 1613)))


def wire_s(baudrate: int) -> float:
    return (len(REQUEST) + 16) * 11 / baudrate + DELAY_S


def summary(values: list[float]) -> tuple[float, float, float]:
    ordered = sorted(values)
    return statistics.median(ordered), ordered[int(0.9 * (len(ordered) - 1))], ordered[-1]


def through_pty(baudrate: int, count: int) -> list[float]:
    """Durations seen by a pyserial client of ``fcmaster sim`` in another process."""
    with tempfile.TemporaryDirectory() as directory:
        link = os.path.join(directory, "tty")
        command = [sys.executable, "-m", "fcmaster", "sim", "--baudrate", str(baudrate),
                   "--link", link, "--addresses", "1"]  # fmt: skip
        with subprocess.Popen(command, stdout=subprocess.PIPE, text=True) as server:
            try:
                assert server.stdout is not None
                server.stdout.readline()
                took = []
                with serial.Serial(link, baudrate, parity="E", timeout=1.0) as port:
                    for _ in range(count):
                        written = time.monotonic()
                        port.write(REQUEST)
                        if len(port.read(16)) != 16:
                            raise RuntimeError("no reply")
                        took.append(time.monotonic() - written)
                return took
            finally:
                server.send_signal(signal.SIGTERM)
                server.wait(timeout=10)


async def in_process(baudrate: int, count: int) -> tuple[list[float], list[float]]:
    """Request arrival → read returned, and reply delivered → next request, in-process."""
    clock = MonotonicClock()
    line = build_line(LineSettings(baudrate=baudrate), [(1, DriveSettings())], clock=clock)
    transport = SimTransport(line, clock)
    await transport.open()
    took, gaps = [], []
    for _ in range(count):
        await transport.write(REQUEST)
        framer = FcFramer()
        while True:
            framer.feed(await transport.read(clock.now() + 1.0))
            if isinstance(framer.next_frame(), Frame):
                break
        took.append(clock.now() - line.transactions[-1].request_at)
    records = list(line.transactions)
    for before, after in itertools.pairwise(records):
        assert before.reply_end is not None
        gaps.append(after.request_at - before.reply_end)
    return took, gaps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=300)
    parser.add_argument("--bauds", default="9600,19200,115200")
    args = parser.parse_args()
    print(f"FC parameter poll, 16 + 16 bytes 8E1, 8-35 = {DELAY_S * 1000:.0f} ms, n = {args.count}")
    print(f"{'baud':>7} {'wire ms':>8} | {'pty ratio med / p90 / max':>27} | "
          f"{'in-process ratio med / p90 / max':>33} | {'gap µs med / p90':>16}")  # fmt: skip
    for baudrate in (int(b) for b in args.bauds.split(",")):
        wire = wire_s(baudrate)
        pty = summary([t / wire for t in through_pty(baudrate, args.count)])
        with asyncio.Runner(loop_factory=new_event_loop) as runner:
            took, gaps = runner.run(in_process(baudrate, args.count))
        inproc = summary([t / wire for t in took])
        gap = summary(gaps)
        print(f"{baudrate:>7} {wire * 1000:>8.3f} | "
              f"{pty[0]:>8.3f} / {pty[1]:>6.3f} / {pty[2]:>6.3f}   | "
              f"{inproc[0]:>12.4f} / {inproc[1]:>6.4f} / {inproc[2]:>6.4f}  | "
              f"{gap[0] * 1e6:>7.0f} / {gap[1] * 1e6:>6.0f}")  # fmt: skip


if __name__ == "__main__":
    main()
