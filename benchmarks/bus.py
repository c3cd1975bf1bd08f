"""The real bus master against the timed simulator over a pty: efficiency, overhead, CPU.

Run: ``python benchmarks/bus.py [--quick] [--duration S] [--output PATH] [--repeat N]
[--loop precise|epoll|both] [--case DRIVES,BAUD,DELAY_MS]… [--no-floors] [--realtime]``
(``--quick``: 3 s per case instead of 10; the default run takes about 4 minutes).
``--repeat N`` runs everything N times and judges the per-case medians (the machine is
shared: one run can meet a burst of other work). ``--realtime`` runs master and simulator
under SCHED_FIFO, as on a gateway whose CPU is the master's when it needs it.

Cases: 32 and 126 FC drives, 19200 and 115200 baud (8E1: 11 bits a character), 10 ms and
5 ms response delay. Each case runs the master twice against the same simulator: under
fcmaster's precise event loop (:func:`fcmaster.clock.new_event_loop`, as the daemon runs)
and under asyncio's default loop (epoll) for comparison.

* The simulator runs in its **own process** (this script started with ``--serve-sim``: the
  same :func:`~fcmaster.sim.build_line` and :class:`~fcmaster.sim.PtyServer` as
  ``fcmaster sim``, under the precise loop), so the master's CPU time is its own and the
  two never share a loop or a GIL. It reports what it heard and sent (its ``transactions``
  record and its timer wake-ups) over a pipe after each run. Its replies leave on time:
  its clock (:class:`~fcmaster.clock.MonotonicClock`, allowed a lead of up to
  ``SIM_MAX_LEAD_S``) learns how late the kernel wakes it and wakes that much sooner, so
  the reply's last byte is written when the wire would deliver it (its residual lateness
  is reported). What it cannot hide is the pty itself
  and its own wake-up when a request arrives: a real UART has neither.
* The master is the real :class:`~fcmaster.bus.master.BusMaster` on the real
  :class:`~fcmaster.transport.serial.SerialTransport`, opening the pty slave. Every drive is
  monitor-only with the default monitor list, so every poll is a 16-byte parameter
  telegram answered by 16 bytes. Logging is at ``warning`` (the daemon's ``info`` would
  add a line per command completed). The transport is wrapped by :class:`TapTransport`,
  which only notes the time of each write and, for each read that returned bytes, when
  they reached the port (the transport's ``received_at``, stamped by its reader callback);
  nothing in ``fcmaster/`` is changed. The master's clock is a :class:`RecordingClock`.
* Commands: ``read 3-41`` (not in the monitor list, so its telegram is unmistakable) on a
  random drive, one at a time, each submitted a random 0…4 transaction times after the
  previous one ended, i.e. at a random phase of the transaction in flight.

Figures, over a fixed window after a warm-up (both ends on ``time.monotonic``, which is
one clock for both processes):

* **line efficiency** = replies per second (the master's LineStats) ÷ the limit 1 / T, with
  T = (16 + 16) × 11 / baud + response delay + the master's pause (2 characters for FC);
* **master overhead** = from the moment the bytes that completed a reply reached the
  master's port to the next request's write, minus the pause (median, p99), as the master
  sees it;
* **line gap** = the same gap as the simulator sees the wire: from the reply's last byte
  (its scheduled end) to the next request's first byte heard, minus the pause. It adds
  the pty both ways and the simulator's own lateness to the master's overhead;
* **command → wire** = from ``execute()`` to the write of the telegram carrying it, in T;
* **CPU** = ``time.process_time()`` of this process per 1000 transactions: the master, its
  event loop, the command source and the thin tap and recording clock of this harness —
  not the simulator, which is another process.
* **where the time goes**: the loss per transaction (mean write-to-write cycle − T) is
  split into request written → heard by the simulator (pty, its wake-up), the simulator's
  timer lateness (reply due → sent), reply sent → its bytes reached the master's port (pty,
  the master's wake-up) and the master's overhead; the four add up to the loss. The overhead is
  split in turn at the master's pause, whose ``sleep_until`` calls a recording clock notes
  (the injected Clock seam; the master's code is unchanged): reply reached the port → the
  start the master counts its pause from ("decode": zero when the pause counts from the
  arrival, as it does; above zero if the master started counting only after decoding),
  the pause's wake-up lateness, and wake-up → write.
* **harness ceiling** = T ÷ (T + the pty both ways + the simulator's lateness + the master's
  wake-up for the reply): the efficiency a master with no overhead at all could reach on
  this harness and machine.
* **the machine's floor** (unless ``--no-floors``): the two simplest masters against the
  same simulator and pty, for scale — a blocking loop on the descriptor (write, select()
  until the 16 bytes are in, sleep out the pause: no asyncio, no framing, no decoding) and
  the same loop on the precise asyncio event loop. Their CPU per 1000 transactions is what
  any master pays on this machine for its wake-ups alone.

The epoll runs reset the thread's timer slack to the default first (the precise loop
lowers it, and the setting would otherwise carry over).

The machine may be shared: the load average is recorded with every case, and wake-up
latencies (hence all the timing figures) grow with it. Benchmarks are not tests: nothing
here passes or fails, the targets are printed for comparison only.
"""

from __future__ import annotations

import argparse
import asyncio
import bisect
import contextlib
import ctypes
import ctypes.util
import itertools
import json
import math
import os
import random
import resource
import select
import subprocess
import sys
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Final

import results_file
import serial

from fcmaster import logsetup
from fcmaster.bus.commands import Action, Command
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock, lower_timer_slack, new_event_loop
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.framing import Framer
from fcmaster.sim import DriveSettings, LineSettings, PtyServer, build_line
from fcmaster.transport.serial import SerialTransport

REQUEST_LENGTH: Final = 16  # FC parameter telegram, both ways
REPLY_LENGTH: Final = 16
COMMAND_PARAMETER: Final = "3-41"  # not in the default monitor list
WARMUP_S: Final = 0.5
SIM_HISTORY: Final = 200_000
SIM_MAX_LEAD_S: Final = 0.001  # the simulator may spin up to 1 ms to send its replies on time
DEFAULT_OUTPUT: Final = Path(__file__).resolve().parent / "results" / "bus.json"
TARGETS: Final = {
    "efficiency_at_10ms": 0.98,
    "efficiency_at_5ms": 0.97,
    "overhead_median_ms": 0.2,
    "overhead_p99_ms": 0.5,
    "cpu_s_per_1000": 0.2,
    "command_to_wire_p99_t": 1.0,
}
_PR_SET_TIMERSLACK: Final = 29
REALTIME_PRIORITY: Final = 10  # --realtime: SCHED_FIFO, above every ordinary process

now = time.monotonic  # MonotonicClock's timebase, and the simulator process's


# -- both sides ------------------------------------------------------------------------


class RecordingClock(MonotonicClock):
    """The real clock, noting ``(called, deadline, returned)`` for every ``sleep_until``.

    Both sides take one: the simulator's timed sends and the master's pauses are the only
    callers, so the notes say how late each woke. The clock is the injected seam, so the
    master's own code is unchanged; the wrapper costs one coroutine frame per sleep.
    """

    __slots__ = ("sleeps",)

    def __init__(self, *, max_lead_s: float = 0.0001) -> None:
        super().__init__(max_lead_s=max_lead_s)
        self.sleeps: list[tuple[float, float, float]] = []

    async def sleep_until(self, deadline: float) -> None:
        called = now()
        await super().sleep_until(deadline)
        self.sleeps.append((called, deadline, now()))


# -- the simulator process ---------------------------------------------------------------


async def _serve_sim(baudrate: int, delay_s: float, drives: int) -> None:
    """Serve the line on a pty; print its path; on each stdin line print the record so far."""
    clock = RecordingClock(max_lead_s=SIM_MAX_LEAD_S)
    line = build_line(
        LineSettings(name="bench", baudrate=baudrate),
        [(address, DriveSettings(response_delay_s=delay_s)) for address in range(1, drives + 1)],
        clock=clock,
    )
    line.transactions = deque(maxlen=SIM_HISTORY)
    loop = asyncio.get_running_loop()
    async with PtyServer(line, clock=clock) as server:
        print(server.device, flush=True)
        cpu = time.process_time()
        while await loop.run_in_executor(None, sys.stdin.readline):
            cpu_now = time.process_time()
            record = {
                "transactions": [
                    (t.request_at, t.reply_end, ",".join(t.faults)) for t in line.transactions
                ],
                "wakes": [(deadline, woke) for _, deadline, woke in clock.sleeps],
                "cpu_s": cpu_now - cpu,
            }
            print(json.dumps(record), flush=True)
            line.transactions.clear()
            clock.sleeps = []
            cpu = cpu_now


@dataclass(slots=True)
class SimRecord:
    """What the simulator saw since the previous record."""

    transactions: list[tuple[float, float | None]]  # first request byte heard, reply end
    wakes: dict[float, float]  # its timed sends: due → woke
    cpu_s: float
    faults: list[tuple[float, str]]  # requests that met a fault (collision, …): when, which


class SimProcess:
    """``--serve-sim`` in a child process, talked to over its stdin and stdout."""

    def __init__(self, baudrate: int, delay_s: float, drives: int) -> None:
        spec = f"{baudrate},{delay_s},{drives}"
        command = [sys.executable, os.path.abspath(__file__), "--serve-sim", spec]
        self._process = subprocess.Popen(
            command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )
        self.path = self._stdout.readline().strip()
        if not self.path:
            self.close()
            raise RuntimeError(f"the simulator did not start ({spec})")

    @property
    def _stdout(self) -> IO[str]:
        assert self._process.stdout is not None
        return self._process.stdout

    def record(self) -> SimRecord:
        """Everything since the last call (blocks for a few milliseconds)."""
        assert self._process.stdin is not None
        self._process.stdin.write("record\n")
        self._process.stdin.flush()
        data = json.loads(self._stdout.readline())
        return SimRecord(
            transactions=[(t[0], t[1]) for t in data["transactions"]],
            wakes={due: woke for due, woke in data["wakes"]},
            cpu_s=data["cpu_s"],
            faults=[(t[0], t[2]) for t in data["transactions"] if t[2]],
        )

    def close(self) -> None:
        """End the child (EOF on its stdin), or kill it if it does not go."""
        with contextlib.suppress(OSError):
            if self._process.stdin is not None:
                self._process.stdin.close()
        try:
            self._process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait()
        if self._process.stdout is not None:
            self._process.stdout.close()


@contextlib.contextmanager
def simulator(baudrate: int, delay_s: float, drives: int) -> Iterator[SimProcess]:
    """A simulator process for the duration of the block."""
    process = SimProcess(baudrate, delay_s, drives)
    try:
        yield process
    finally:
        process.close()


# -- the master side -------------------------------------------------------------------


class TapTransport:
    """SerialTransport, noting when each write starts and when the bytes of each read came."""

    def __init__(self, inner: SerialTransport) -> None:
        self.inner = inner
        self.writes: list[float] = []
        self.reads: list[float] = []
        self.expected: dict[bytes, float] = {}  # a command's request → when it was submitted
        self.commands: list[tuple[float, float]] = []  # (submitted, written)

    async def open(self) -> None:
        await self.inner.open()

    async def close(self) -> None:
        await self.inner.close()

    async def write(self, data: bytes) -> None:
        at = now()
        self.writes.append(at)
        if self.expected:
            submitted = self.expected.pop(data, None)
            if submitted is not None:
                self.commands.append((submitted, at))
        await self.inner.write(data)

    async def read(self, deadline: float) -> bytes:
        data = await self.inner.read(deadline)
        self.reads.append(self.inner.received_at)  # when the bytes reached the port
        return data

    def write_now(self, data: bytes) -> None:
        self.writes.append(now())
        self.inner.write_now(data)

    def watch_frame(
        self, framer: Framer, deadline: float, gap_s: float, handler: Callable[[Any], None]
    ) -> Any:
        def noted(piece: Any) -> None:
            if piece is not None:
                self.reads.append(self.inner.received_at)  # when the bytes reached the port
            handler(piece)

        piece = self.inner.watch_frame(framer, deadline, gap_s, noted)
        if piece is not None:
            self.reads.append(self.inner.received_at)
        return piece

    def unwatch(self) -> None:
        self.inner.unwatch()

    def check_open(self) -> None:
        self.inner.check_open()

    @property
    def framing(self) -> TapTransport:
        return self

    @property
    def adapter(self) -> Any:
        return self.inner.adapter

    async def appeared(self) -> None:
        await self.inner.appeared()

    @property
    def received_at(self) -> float:
        return self.inner.received_at

    def discard_input(self) -> bytes:
        return self.inner.discard_input()


@dataclass(slots=True, frozen=True)
class Case:
    """One line configuration."""

    drives: int
    baudrate: int
    delay_s: float

    def line_plan(self, port: str, *, with_drives: bool = True) -> LinePlan:
        """The master's plan: monitor-only drives at 1…N with the default monitor list."""
        drives = range(1, self.drives + 1) if with_drives else ()
        return LinePlan(
            name="bench",
            port=port,
            baudrate=self.baudrate,
            response_delay_s=self.delay_s,
            drives=tuple(DrivePlan(name=f"d{a}", address=a) for a in drives),
        )

    @property
    def pause_s(self) -> float:
        """The pause the master keeps after a reply (FC: two characters)."""
        return FcCodec().min_pause_s(self.line_plan("", with_drives=False).char_s)

    @property
    def transaction_s(self) -> float:
        """T: both telegrams on the wire, the response delay and the pause."""
        wire_s = self.line_plan("", with_drives=False).wire_s(REQUEST_LENGTH + REPLY_LENGTH)
        return wire_s + self.delay_s + self.pause_s


@dataclass(slots=True)
class MasterRecord:
    """What one master run saw in its window."""

    start: float
    end: float
    replies: int
    timeouts: int
    cpu_s: float
    user_s: float
    system_s: float
    switches: int  # voluntary context switches: the times the process slept
    preempted: int  # involuntary ones: the times it was made to wait for a CPU
    writes: list[float]
    reads: list[float]
    sleeps: list[tuple[float, float, float]]  # the master's pauses: called, deadline, returned
    commands: list[tuple[float, float]]
    commands_failed: int


async def _issue_commands(
    master: BusMaster, tap: TapTransport, case: Case, rng: random.Random, failed: list[int]
) -> None:
    codec = master.codec
    key = codec.parameter(COMMAND_PARAMETER)
    command = Command(action=Action.READ, parameter=COMMAND_PARAMETER, actor="bench")
    drives = master.plan.drives
    longest_s = 4.0 * case.transaction_s
    while True:
        await asyncio.sleep(rng.uniform(0.0, longest_s))
        drive = rng.choice(drives)
        (exchange,) = codec.read(drive.address, key, 0, None)  # monitor-only: no intent
        request = exchange.request
        tap.expected[request] = now()
        result = await master.execute(drive.name, command)
        tap.expected.pop(request, None)
        if not result.ok:
            failed[0] += 1


async def run_master(case: Case, path: str, duration_s: float, seed: int) -> MasterRecord:
    """Poll the simulator for ``duration_s`` (after a warm-up) and record the window."""
    plan = case.line_plan(path)
    tap = TapTransport(SerialTransport(path, baudrate=plan.baudrate, parity=plan.parity))
    clock = RecordingClock()
    async with BusMaster(plan, codec=FcCodec(), transport=tap, clock=clock) as master:
        if not master.is_up:
            raise RuntimeError(f"the master could not open {path}")
        await asyncio.sleep(WARMUP_S)
        stats = master.stats
        replies, timeouts = stats.replies, stats.timeouts
        failed = [0]
        usage, cpu, start = resource.getrusage(resource.RUSAGE_SELF), time.process_time(), now()
        commander = asyncio.create_task(
            _issue_commands(master, tap, case, random.Random(seed), failed), name="bench.commands"
        )
        try:
            await asyncio.sleep(duration_s)
        finally:
            end, cpu = now(), time.process_time() - cpu
            after = resource.getrusage(resource.RUSAGE_SELF)
            replies, timeouts = stats.replies - replies, stats.timeouts - timeouts
            commander.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await commander
    return MasterRecord(
        start=start,
        end=end,
        replies=replies,
        timeouts=timeouts,
        cpu_s=cpu,
        user_s=after.ru_utime - usage.ru_utime,
        system_s=after.ru_stime - usage.ru_stime,
        switches=after.ru_nvcsw - usage.ru_nvcsw,
        preempted=after.ru_nivcsw - usage.ru_nivcsw,
        writes=tap.writes,
        reads=tap.reads,
        sleeps=clock.sleeps,
        commands=[c for c in tap.commands if start <= c[0] <= end],
        commands_failed=failed[0],
    )


# -- the machine's floor -----------------------------------------------------------------


async def warmed_up(master: BusMaster) -> None:
    """Wait the warm-up, and until as many replies came as ``master`` has idle polls.

    A line polls each drive through its monitor list, one parameter a poll, and the master
    encodes each of those polls and parses each distinct reply once, then finds them in its
    caches for as long as the daemon runs. The first pass over a fleet (32 drives × 7
    parameters is 224 polls, 5.5 s at 19200 baud) is start-up, not the steady cost a
    transaction has for months, so CPU is measured after it.
    """
    polls = sum(len(slot.sequence) for slot in master.planner.slots)
    await asyncio.sleep(WARMUP_S)
    for _ in range(2400):  # 2 minutes at most: a line that stopped answering ends it
        if master.stats.replies >= polls:
            return
        await asyncio.sleep(0.05)


def poll_requests(case: Case) -> list[bytes]:
    """One 16-byte parameter poll (16-13) for each drive of ``case``, as the floors send."""
    codec = FcCodec()
    key = codec.parameter("16-13")
    return [codec.read(a, key, 0, None)[0].request for a in range(1, case.drives + 1)]


def open_raw(case: Case, path: str) -> serial.Serial:
    """The pty, configured by pyserial (without parity: a pty carries none)."""
    return serial.Serial(path, baudrate=case.baudrate, timeout=0)


def _floor_row(
    case: Case, kind: str, replies: int, elapsed: float, cpu_s: float, usage: Any, after: Any
) -> dict[str, Any]:
    replies_or_1 = replies or 1
    return {
        "drives": case.drives,
        "baudrate": case.baudrate,
        "response_delay_ms": case.delay_s * 1000,
        "floor": kind,
        "efficiency": replies / elapsed * case.transaction_s,
        "cpu_s_per_1000": cpu_s / replies_or_1 * 1000,
        "sleeps_per_transaction": (after.ru_nvcsw - usage.ru_nvcsw) / replies_or_1,
        "load_average": os.getloadavg()[0],
    }


def run_raw_floor(case: Case, path: str, duration_s: float) -> dict[str, Any]:
    """A blocking loop on the descriptor: no asyncio, no framing, no decoding, no planning.

    Write a poll, select() until its 16 bytes are in, sleep out the pause (the last 50 µs
    spun). What a minimal C-like master costs on this machine, through the same pty.
    """
    lower_timer_slack()
    requests, pause = poll_requests(case), case.pause_s
    port = open_raw(case, path)
    fd = port.fileno()

    def cycle(until: float) -> int:
        count = 0
        for request in itertools.cycle(requests):
            written = now()
            if written >= until:
                return count
            os.write(fd, request)
            got = 0
            while got < REPLY_LENGTH:
                ready, _, _ = select.select([fd], [], [], max(0.0, written + 0.1 - now()))
                if not ready:
                    break
                got += len(os.read(fd, 256))
            count += got >= REPLY_LENGTH
            ready_at = now() + pause
            time.sleep(max(0.0, pause - 50e-6))  # noqa: TID251 (no event loop here)
            while now() < ready_at:
                pass
        return count

    try:
        cycle(now() + WARMUP_S)
        usage, cpu, start = resource.getrusage(resource.RUSAGE_SELF), time.process_time(), now()
        replies = cycle(start + duration_s)
        elapsed, cpu = now() - start, time.process_time() - cpu
        after = resource.getrusage(resource.RUSAGE_SELF)
    finally:
        port.close()
    return _floor_row(case, "raw fd loop", replies, elapsed, cpu, usage, after)


async def run_asyncio_floor(case: Case, path: str, duration_s: float) -> dict[str, Any]:
    """The same on the precise event loop: a reader callback, one future and one timer per
    reply, the pause on :class:`MonotonicClock`. What asyncio itself costs on this machine.
    """
    requests, pause = poll_requests(case), case.pause_s
    loop, clock = asyncio.get_running_loop(), MonotonicClock()
    port = open_raw(case, path)
    fd = port.fileno()
    received = bytearray()
    waiter: list[asyncio.Future[None]] = []

    def on_readable() -> None:
        received.extend(os.read(fd, 256))
        if len(received) >= REPLY_LENGTH and waiter and not waiter[0].done():
            waiter[0].set_result(None)

    async def cycle(until: float) -> int:
        count = 0
        for request in itertools.cycle(requests):
            if now() >= until:
                return count
            received.clear()
            waiter[:] = [loop.create_future()]
            os.write(fd, request)
            timer = loop.call_at(now() + 0.1, waiter[0].cancel)
            try:
                await waiter[0]
                count += 1
            except asyncio.CancelledError:
                pass  # no reply: go on
            finally:
                timer.cancel()
            await clock.sleep_until(now() + pause)
        return count

    loop.add_reader(fd, on_readable)
    try:
        await cycle(now() + WARMUP_S)
        usage, cpu, start = resource.getrusage(resource.RUSAGE_SELF), time.process_time(), now()
        replies = await cycle(start + duration_s)
        elapsed, cpu = now() - start, time.process_time() - cpu
        after = resource.getrusage(resource.RUSAGE_SELF)
    finally:
        loop.remove_reader(fd)
        port.close()
    return _floor_row(case, "asyncio fd loop", replies, elapsed, cpu, usage, after)


def run_floors(case: Case, duration_s: float) -> list[dict[str, Any]]:
    """Both floors for ``case``, against one simulator process."""
    with simulator(case.baudrate, case.delay_s, case.drives) as sim:
        rows = [run_raw_floor(case, sim.path, duration_s)]
        with asyncio.Runner(loop_factory=new_event_loop) as runner:
            rows.append(runner.run(run_asyncio_floor(case, sim.path, duration_s)))
    for row in rows:
        print(
            f"{row['drives']:>6} {row['baudrate']:>6} {row['response_delay_ms']:>3.0f}ms "
            f"{row['floor']:<16} | eff {row['efficiency']:.3f} | CPU s/1k "
            f"{row['cpu_s_per_1000']:.3f} | sleeps/txn {row['sleeps_per_transaction']:.2f} | "
            f"load {row['load_average']:.2f}",
            flush=True,
        )
    return rows


# -- figures ---------------------------------------------------------------------------


def percentile(values: Sequence[float], q: float) -> float:
    """The ``q`` quantile (0…1) by linear interpolation; NaN when there are no values."""
    if not values:
        return math.nan
    ordered = sorted(values)
    position = q * (len(ordered) - 1)
    low = math.floor(position)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (ordered[high] - ordered[low]) * (position - low)


def mean(values: Sequence[float]) -> float:
    return sum(values) / len(values) if values else math.nan


def spread(values: Sequence[float], scale: float = 1.0) -> dict[str, float | int]:
    """Median, p99, mean and max of ``values`` × ``scale``, and how many there were."""
    scaled = [v * scale for v in values]
    return {
        "median": percentile(scaled, 0.5),
        "p99": percentile(scaled, 0.99),
        "mean": mean(scaled),
        "max": max(scaled) if scaled else math.nan,
        "n": len(scaled),
    }


def analyse(case: Case, loop: str, master: MasterRecord, sim: SimRecord) -> dict[str, Any]:
    """Every figure of one run, as JSON-ready values (times in ms, latencies in T)."""
    t, pause = case.transaction_s, case.pause_s
    start, end = master.start, master.end
    writes, reads = master.writes, master.reads
    pauses = [sleep for sleep in master.sleeps if start <= sleep[0] <= end]
    called_at = [sleep[0] for sleep in pauses]

    def reply_read(index: int) -> float | None:
        """When the reply to write ``index`` was read: the last read before the next write."""
        if index + 1 >= len(writes):
            return None
        last = bisect.bisect_left(reads, writes[index + 1]) - 1
        return reads[last] if last >= 0 and reads[last] > writes[index] else None

    # The master's side: write → write, and the turnaround split at its pause.
    cycles, overhead, decode, wake_late, send = [], [], [], [], []
    overran = 0  # turnarounds whose work outlasted the pause (no sleep at all)
    for i in range(bisect.bisect_left(writes, start), len(writes) - 1):
        if writes[i + 1] > end:
            break
        cycles.append(writes[i + 1] - writes[i])
        read_at = reply_read(i)
        if read_at is None:
            continue
        overhead.append(writes[i + 1] - read_at - pause)
        j = bisect.bisect_right(called_at, read_at)
        if j < len(pauses) and pauses[j][0] < writes[i + 1]:
            _, deadline, returned = pauses[j]
            decode.append(deadline - pause - read_at)  # reply reached the port → the pause began
            wake_late.append(returned - deadline)
            send.append(writes[i + 1] - returned)
        else:
            overran += 1

    # The wire as the simulator saw it, matched to the master's writes and reads.
    line_gap, forward, sim_late, back = [], [], [], []
    heard = [(at, reply_end) for at, reply_end in sim.transactions if start <= at <= end]
    for (_, reply_end), (next_at, _) in itertools.pairwise(heard):
        if reply_end is not None:
            line_gap.append(next_at - reply_end - pause)
    for at, reply_end in heard:
        i = bisect.bisect_right(writes, at) - 1
        if i < 0:
            continue
        forward.append(at - writes[i])  # written → first byte heard by the simulator
        read_at = reply_read(i)
        woke = sim.wakes.get(reply_end) if reply_end is not None else None
        if reply_end is None or woke is None or read_at is None:
            continue
        sim_late.append(woke - reply_end)  # the reply's last byte due → the simulator sent it
        back.append(read_at - woke)  # sent → its bytes reached the master's port

    elapsed = end - start
    replies = master.replies or 1
    achieved = master.replies / elapsed
    waits = [(written - submitted) / t for submitted, written in master.commands]
    ms = 1000.0
    return {
        "drives": case.drives,
        "baudrate": case.baudrate,
        "response_delay_ms": case.delay_s * ms,
        "loop": loop,
        "window_s": elapsed,
        "transaction_ms": t * ms,
        "pause_ms": pause * ms,
        "limit_per_s": 1.0 / t,
        "achieved_per_s": achieved,
        "efficiency": achieved * t,
        "replies": master.replies,
        "timeouts": master.timeouts,
        "faults": [fault for at, fault in sim.faults if start <= at <= end],
        # What this harness allows a master with no overhead at all: T over T plus the
        # pty both ways, the simulator's lateness and the master's wake-up for the reply.
        "harness_ceiling": t / (t + mean(forward) + mean(sim_late) + mean(back)),
        "overhead_ms": spread(overhead, ms),
        "line_gap_ms": spread(line_gap, ms),
        "command_to_wire_t": spread(waits),
        "commands_failed": master.commands_failed,
        "cpu_s_per_1000": master.cpu_s / replies * 1000,
        "cycle_ms": spread(cycles, ms),
        # Mean ms per transaction; the four parts add up to cycle - T.
        "loss_ms": {
            "cycle_minus_t": (mean(cycles) - t) * ms,
            "request_to_sim": mean(forward) * ms,
            "sim_late": mean(sim_late) * ms,
            "sim_to_master_read": mean(back) * ms,
            "master_overhead": mean(overhead) * ms,
        },
        # Mean ms; the three add up to the master's overhead (turnarounds with a pause).
        "overhead_split_ms": {
            "read_to_pause_start": mean(decode) * ms,
            "pause_woke_late": mean(wake_late) * ms,
            "woke_to_write": mean(send) * ms,
            "overran_pause": overran,
        },
        "request_to_sim_ms": spread(forward, ms),
        "sim_late_ms": spread(sim_late, ms),
        "sim_to_master_read_ms": spread(back, ms),
        "read_to_pause_start_ms": spread(decode, ms),
        "pause_woke_late_ms": spread(wake_late, ms),
        "woke_to_write_ms": spread(send, ms),
        "cpu": {
            "share": master.cpu_s / elapsed,
            "user_ms_per_transaction": master.user_s / replies * ms,
            "system_ms_per_transaction": master.system_s / replies * ms,
            "sleeps_per_transaction": master.switches / replies,
            "preemptions_per_transaction": master.preempted / replies,
            "simulator_share": sim.cpu_s / elapsed,
        },
        "load_average": os.getloadavg()[0],
    }


# -- running ---------------------------------------------------------------------------


def _reset_timer_slack() -> None:
    """Give this thread the default timer slack back (the precise loop lowers it)."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
            libc.prctl(_PR_SET_TIMERSLACK, 0, 0, 0, 0)


def _default_loop() -> asyncio.AbstractEventLoop:
    _reset_timer_slack()
    return asyncio.new_event_loop()


LOOPS: Final[dict[str, Callable[[], asyncio.AbstractEventLoop]]] = {
    "precise": new_event_loop,
    "epoll": _default_loop,
}


def run_case(
    case: Case, duration_s: float, seed: int, loops: Sequence[str] = tuple(LOOPS)
) -> list[dict[str, Any]]:
    """The case under each of ``loops``, against one simulator process."""
    rows = []
    with simulator(case.baudrate, case.delay_s, case.drives) as sim:
        for loop in loops:
            factory = LOOPS[loop]
            sim.record()  # drop what came before
            with asyncio.Runner(loop_factory=factory) as runner:
                master = runner.run(run_master(case, sim.path, duration_s, seed))
            rows.append(analyse(case, loop, master, sim.record()))
            print_row(rows[-1])
    return rows


HEADER: Final = (
    f"{'drives':>6} {'baud':>6} {'delay':>5} {'loop':<7} | {'T ms':>6} {'limit/s':>7} "
    f"{'got/s':>7} {'eff':>6} | {'ovh ms med':>10} {'p99':>6} | {'gap ms med':>10} {'p99':>6} | "
    f"{'cmd→wire T med':>14} {'p99':>5} {'n':>4} | {'CPU s/1k':>8} | {'load':>4}"
)
SPLIT_HEADER: Final = (
    f"{'drives':>6} {'baud':>6} {'delay':>5} {'loop':<7} | {'cycle-T':>7} = {'→sim':>5} + "
    f"{'simlate':>7} + {'→read':>5} + {'ovh':>5} | {'ovh':>5} = {'decode':>6} + {'late':>5} + "
    f"{'send':>5} {'over':>4} | {'CPU µs':>6} {'user':>5} {'sys':>4} {'sleeps':>6} "
    f"{'preempt':>7} {'sim%':>4} | {'ceiling':>7}"
)


def _case(row: dict[str, Any]) -> str:
    return (
        f"{row['drives']:>6} {row['baudrate']:>6} {row['response_delay_ms']:>3.0f}ms "
        f"{row['loop']:<7}"
    )


def print_row(row: dict[str, Any]) -> None:
    ovh, gap, cmd = row["overhead_ms"], row["line_gap_ms"], row["command_to_wire_t"]
    print(
        f"{_case(row)} | {row['transaction_ms']:>6.2f} {row['limit_per_s']:>7.2f} "
        f"{row['achieved_per_s']:>7.2f} {row['efficiency']:>6.3f} | "
        f"{ovh['median']:>10.3f} {ovh['p99']:>6.3f} | {gap['median']:>10.3f} {gap['p99']:>6.3f} | "
        f"{cmd['median']:>14.2f} {cmd['p99']:>5.2f} {cmd['n']:>4} | "
        f"{row['cpu_s_per_1000']:>8.3f} | {row['load_average']:>4.2f}",
        flush=True,
    )
    if row["timeouts"] or row["commands_failed"] or row["faults"]:
        print(
            f"{'':>28}!! {row['timeouts']} timeouts, {row['commands_failed']} commands "
            f"failed, faults on the line: {', '.join(row['faults']) or 'none'}",
            flush=True,
        )


def print_split(row: dict[str, Any]) -> None:
    loss = {k: v * 1000 for k, v in row["loss_ms"].items()}
    split = row["overhead_split_ms"]
    cpu = row["cpu"]
    print(
        f"{_case(row)} | {loss['cycle_minus_t']:>7.0f} = {loss['request_to_sim']:>5.0f} + "
        f"{loss['sim_late']:>7.0f} + {loss['sim_to_master_read']:>5.0f} + "
        f"{loss['master_overhead']:>5.0f} | {loss['master_overhead']:>5.0f} = "
        f"{split['read_to_pause_start'] * 1000:>6.0f} + {split['pause_woke_late'] * 1000:>5.0f} + "
        f"{split['woke_to_write'] * 1000:>5.0f} {split['overran_pause']:>4} | "
        f"{row['cpu_s_per_1000'] * 1000:>6.0f} {cpu['user_ms_per_transaction'] * 1000:>5.0f} "
        f"{cpu['system_ms_per_transaction'] * 1000:>4.0f} {cpu['sleeps_per_transaction']:>6.2f} "
        f"{cpu['preemptions_per_transaction']:>7.2f} {cpu['simulator_share'] * 100:>4.1f} | "
        f"{row['harness_ceiling']:>7.3f}"
    )


def median_rows(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per case and loop: the median of every figure over its repeated runs."""
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for row in rows:
        key = (row["drives"], row["baudrate"], row["response_delay_ms"], row["loop"])
        groups.setdefault(key, []).append(row)
    return [_median(group) for group in groups.values()]


def _median(values: Sequence[Any]) -> Any:
    first = values[0]
    if all(value == first for value in values):
        return first
    if isinstance(first, dict):
        return {key: _median([value[key] for value in values]) for key in first}
    if isinstance(first, float | int) and not isinstance(first, bool):
        middle = percentile([float(v) for v in values], 0.5)
        return round(middle) if isinstance(first, int) else middle
    return first


def verdicts(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Each row against the targets, in words (for reading, not for failing)."""
    lines = []
    for row in rows:
        target = TARGETS["efficiency_at_10ms" if row["response_delay_ms"] >= 10 else
                         "efficiency_at_5ms"]  # fmt: skip
        checks = [
            (f"eff {row['efficiency']:.3f} ≥ {target}", row["efficiency"] >= target),
            (
                f"ovh med {row['overhead_ms']['median']:.3f} ≤ {TARGETS['overhead_median_ms']}",
                row["overhead_ms"]["median"] <= TARGETS["overhead_median_ms"],
            ),
            (
                f"ovh p99 {row['overhead_ms']['p99']:.3f} ≤ {TARGETS['overhead_p99_ms']}",
                row["overhead_ms"]["p99"] <= TARGETS["overhead_p99_ms"],
            ),
            (
                f"CPU {row['cpu_s_per_1000']:.3f} ≤ {TARGETS['cpu_s_per_1000']}",
                row["cpu_s_per_1000"] <= TARGETS["cpu_s_per_1000"],
            ),
            (
                f"cmd p99 {row['command_to_wire_t']['p99']:.2f} T ≤ "
                f"{TARGETS['command_to_wire_p99_t']}",
                row["command_to_wire_t"]["p99"] <= TARGETS["command_to_wire_p99_t"],
            ),
        ]
        missed = [text for text, ok in checks if not ok]
        name = (
            f"{row['drives']:>3} drives {row['baudrate']:>6} {row['response_delay_ms']:>2.0f} ms "
            f"{row['loop']:<7}"
        )
        verdict = "misses: " + "; ".join(missed) if missed else "meets every target"
        lines.append(f"{name} {verdict}")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="3 s per case instead of 10")
    parser.add_argument("--duration", type=float, help="seconds per case and loop")
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT, help="the JSON results")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument(
        "--loop", choices=(*LOOPS, "both"), default="both", help="which event loop(s) to run"
    )
    parser.add_argument(
        "--case",
        action="append",
        metavar="DRIVES,BAUD,DELAY_MS",
        help="run only this case (repeatable), e.g. 126,115200,5",
    )
    parser.add_argument(
        "--repeat", type=int, default=1, help="run every case N times; judge their medians"
    )
    parser.add_argument(
        "--no-floors", action="store_true", help="skip the raw and asyncio floor loops"
    )
    parser.add_argument(
        "--realtime",
        action="store_true",
        help="run master and simulator under SCHED_FIFO (needs the privilege): a CPU as a "
        "dedicated gateway has it, whatever else the machine runs",
    )
    parser.add_argument("--serve-sim", help=argparse.SUPPRESS)  # BAUD,DELAY_S,DRIVES: the child
    args = parser.parse_args(argv)
    if args.serve_sim:
        baudrate, delay_s, drives = args.serve_sim.split(",")
        with asyncio.Runner(loop_factory=new_event_loop) as runner:
            runner.run(_serve_sim(int(baudrate), float(delay_s), int(drives)))
        return 0

    logsetup.configure(level="warning")
    if args.realtime:  # the simulator processes inherit it
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(REALTIME_PRIORITY))
    duration_s = args.duration or (3.0 if args.quick else 10.0)
    cases = [
        Case(drives, baudrate, delay_ms / 1000)
        for drives in (32, 126)
        for baudrate in (19200, 115200)
        for delay_ms in (10, 5)
    ]
    if args.case:
        wanted = {tuple(float(v) for v in spec.split(",")) for spec in args.case}
        cases = [c for c in cases if (c.drives, c.baudrate, c.delay_s * 1000) in wanted]
    loops = tuple(LOOPS) if args.loop == "both" else (args.loop,)
    print(
        f"FC parameter polls (16 + 16 bytes, 8E1), monitor-only drives, 'read {COMMAND_PARAMETER}'"
        f" commands at random moments; simulator in its own process on a pty; {duration_s:g} s "
        f"per case and loop after {WARMUP_S:g} s warm-up; {os.cpu_count()} CPUs, "
        f"load {os.getloadavg()[0]:.2f}{', SCHED_FIFO' if args.realtime else ''}"
    )
    print(HEADER, flush=True)
    started = now()
    rows = []
    for run in range(args.repeat):
        for case in cases:
            for row in run_case(case, duration_s, args.seed + run, loops):
                rows.append({**row, "run": run})
    summary = median_rows(rows) if args.repeat > 1 else rows
    floors = []
    if not args.no_floors:
        print("\nThe machine's floor: the simplest masters on the same simulator and pty")
        for case in {(c.baudrate, c.delay_s): c for c in reversed(cases)}.values():
            floors += run_floors(case, duration_s)
    print()
    print("Where the time goes, mean µs per transaction: cycle - T = request written → heard by")
    print("the simulator + its timer's lateness + reply sent → reached the master's port + the")
    print("master's overhead; which = arrival → pause counted from (decode) + the pause's wake-up")
    print("lateness + wake → next write; 'over': turnarounds that outlasted the pause. CPU µs")
    print("per transaction (user, system), voluntary sleeps and preemptions per transaction,")
    print("the simulator process's CPU share; the efficiency this harness allows a master with no")
    print("overhead at all (T ÷ (T + the pty both ways + the simulator's lateness + the master's")
    print("wake-up for the reply)):")
    print(SPLIT_HEADER)
    for row in rows:
        print_split(row)
    if args.repeat > 1:
        print(f"\nMedians of {args.repeat} runs:")
        print(HEADER)
        for row in summary:
            print_row(row)
    print()
    print("Targets (eff ≥ 0.98 at 10 ms, ≥ 0.97 at 5 ms; overhead med ≤ 0.2 ms, p99 ≤ 0.5 ms;")
    print("CPU ≤ 0.2 s per 1000 transactions; command → wire p99 ≤ 1 T):")
    for line in verdicts(summary):
        print(f"  {line}")
    results = {
        **results_file.provenance("bus"),
        "duration_s": duration_s,
        "warmup_s": WARMUP_S,
        "wall_s": now() - started,
        "telegram": "FC parameter telegram, 16 bytes each way, 8E1",
        "commands": f"read {COMMAND_PARAMETER} on a random drive, 0-4 T apart",
        "targets": TARGETS,
        "repeat": args.repeat,
        "realtime": args.realtime,
        "cases": rows,
        "summary": summary,
        "floors": floors,
    }
    results_file.write(args.output, results)
    print(f"\n{len(rows)} runs in {now() - started:.0f} s; results in {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
