"""A simulated multi-drop RS-485 line that takes as long as the real wire.

Theory of operation
-------------------
The line is sans-I/O and synchronous: it reads the injected clock's ``now()`` and never
waits. Whoever serves it (:class:`~fcmaster.sim.transport.SimTransport` in-process, or
:class:`~fcmaster.sim.pty.PtyServer`) calls :meth:`SimLine.write` with the master's bytes,
asks :meth:`SimLine.next_delivery` when the next bytes are due, and at that time takes
them with :meth:`SimLine.receive`.

Everything on the wire is a *burst* with a start and an end time. The master's bytes start
when written (or when its own previous bytes have left the UART) and take ``char_s`` each.
Drives hear the bytes through one framer of the protocol (every drive hears the same
bytes, so one receiver stands for all of them); each checked request frame is handed to
every drive at the time its last character ends. A drive answers only when addressed, so at
most one reply burst is scheduled (two drives at one address: two, which collide); it starts
``response_delay_s`` after the request's end. The line never decodes a frame; addressing is
the drives' business.

Bursts that overlap in time collide, as on a half-duplex pair: the characters that overlap
are replaced by garbage in both, so the master's framer rejects the reply and the drives'
framer rejects the request. This is decided when the later burst is scheduled, which is
always early enough: a request is scheduled when written (at or after ``now``), and a reply
only after the request it answers has been heard, so every burst that could overlap a new
one is already known and not yet delivered. The drives' framer is fed the master's burst
byte by byte, so a reply to the first telegram of a burst garbles the telegrams after it
before they are heard.

What reaches the master (replies, noise, and its own echo when the fault plan asks for it)
is delivered whole at the end time of its last character, never sooner — or, with a
:class:`~fcmaster.sim.adapter.LatencyAdapter`, when that adapter's latency timer lets it go.

A master that talks at another baud rate or parity than the line's
(:meth:`SimLine.hear_master_at`, which the pty server calls with the speed a client set) is
heard as garbage: every character is misframed, so no drive answers it, as on a real line.

A pause longer than ``gap_s`` between the master's bytes makes the drives give up an
unfinished request (the framer's ``reset``), as a drive does after 8-37 Maximum
Inter-Char Delay (25 ms by default on FC drives).
"""

from __future__ import annotations

import dataclasses
import heapq
import math
import random
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Final, Protocol

from fcmaster.clock import Clock
from fcmaster.errors import UsageError
from fcmaster.protocol.framing import Frame, Skipped
from fcmaster.sim.adapter import LatencyAdapter
from fcmaster.sim.faults import FaultPlan

DEFAULT_GAP_S: Final = 0.025
DEFAULT_HISTORY: Final = 4096
_MASTER: Final = -1  # source of the master's own bursts
_NOISE: Final = -2


class RequestFramer(Protocol):
    """What the line needs of a protocol's framer (the codec's framers all qualify)."""

    def feed(self, data: bytes) -> None:
        """Append received bytes."""

    def next_frame(self) -> Frame | Skipped | None:
        """Return the next checked frame or skipped piece, or None when more bytes are needed."""

    def reset(self) -> object:
        """Mark an inter-character gap: unfinished frames are given up."""


class SimDrive(Protocol):
    """One simulated drive on a line, of any vendor.

    Every drive hears every checked request frame, as on a real multi-drop bus, and
    returns reply bytes only when addressed. A broadcast is acted on and answered with
    None. ``now`` never goes backwards between calls; physics run lazily up to it.
    """

    @property
    def address(self) -> int:
        """The drive's bus address (1…N); may change when the master rewrites it."""

    @property
    def response_delay_s(self) -> float:
        """Seconds from the end of a request to the start of the reply."""

    def handle(self, frame: bytes, now: float) -> bytes | None:
        """Act on a request that ended at ``now``; return the reply, or None."""


@dataclass(slots=True, kw_only=True)
class Transaction:
    """One request the drives heard and what came of it (times on the line's clock)."""

    request_at: float  # the master's first byte of this request entered the line
    request_end: float  # its last character ended
    request_length: int
    address: int | None = None  # the drive that answered
    reply_start: float | None = None
    reply_end: float | None = None  # when the reply is delivered to the master
    reply_length: int = 0
    faults: list[str] = field(default_factory=list)  # drop, late, corrupt, silent, collision


@dataclass(slots=True)
class LineCounters:
    """Running totals, for tests and benchmarks."""

    requests: int = 0  # checked request frames heard
    replies: int = 0  # replies put on the wire
    dropped: int = 0
    corrupted: int = 0
    late: int = 0
    silenced: int = 0  # replies lost because the drive went silent
    noise_bursts: int = 0
    collisions: int = 0
    skipped_bytes: int = 0  # request bytes the drives' framer threw away
    misframed_bytes: int = 0  # master bytes sent at another baud rate or parity than the line's


@dataclass(slots=True, eq=False)
class _Burst:
    start: float
    end: float
    data: bytearray
    source: int  # drive address, _MASTER or _NOISE
    to_master: bool
    record: Transaction | None = None


class SimLine:
    """Simulated drives on one half-duplex line with wire timing and injected faults."""

    def __init__(
        self,
        *,
        drives: Sequence[SimDrive],
        framer_factory: Callable[[], RequestFramer],
        baudrate: int,
        char_bits: int,
        clock: Clock,
        faults: FaultPlan | None = None,
        drive_faults: Mapping[int, FaultPlan] | None = None,
        rng: random.Random | None = None,
        gap_s: float | None = None,
        history: int = DEFAULT_HISTORY,
        adapter: LatencyAdapter | None = None,
        parity: str | None = None,
    ) -> None:
        """Build the line.

        Args:
            drives: the drives on the line, each at its own address.
            framer_factory: makes the protocol's framer that cuts requests out of the bytes.
            baudrate: bits per second.
            char_bits: bits per character (start + data + parity + stop), e.g. 11 for 8E1.
            clock: the only source of time.
            faults: what goes wrong on the whole line.
            drive_faults: what goes wrong with one drive's replies, by address.
            rng: the seeded source of every random choice; defaults to one seeded from
                ``faults.seed`` (or 0).
            gap_s: a pause between the master's bytes that ends an unfinished request.
            history: how many transactions :attr:`transactions` keeps.
            adapter: a USB adapter that holds what reaches the master (None: none).
            parity: the line's parity (N, E or O), to judge a master's; None: not judged.
        """
        if baudrate <= 0 or char_bits <= 0:
            raise UsageError("baud rate and bits per character must be positive")
        self.faults = faults or FaultPlan()
        drive_faults = drive_faults or {}
        unknown = set(drive_faults) - {drive.address for drive in drives}
        if unknown:
            raise UsageError(f"fault plans for addresses without a drive: {sorted(unknown)}")
        self._drives = [
            (drive, self.faults.merged(drive_faults.get(drive.address, FaultPlan())))
            for drive in drives
        ]
        self._deaf_until = [-math.inf] * len(drives)
        self._framer = framer_factory()
        self.baudrate = baudrate
        self.char_bits = char_bits
        self.char_s = char_bits / baudrate
        self.gap_s = max(3.5 * self.char_s, DEFAULT_GAP_S) if gap_s is None else gap_s
        self._clock = clock
        self._rng = rng or random.Random(self.faults.seed or 0)
        self.epoch = clock.now()
        self.transactions: deque[Transaction] = deque(maxlen=history)
        self.counters = LineCounters()
        self._wire: list[_Burst] = []  # bursts not yet over, for the collision check
        self._deliveries: list[tuple[float, int, _Burst]] = []  # heap by end time
        self._sequence = 0
        self._master_end = -math.inf  # when the master's last written byte leaves the wire
        self._fed = 0  # request bytes given to the framer so far
        self._consumed = 0  # of those, bytes the framer has handed out (frames and skips)
        # stream offset and arrival time of recent writes; enough for a frame sent bytewise
        self._chunks: deque[tuple[int, float]] = deque(maxlen=256)
        self.adapter = adapter
        self.parity = parity
        self.master_baudrate: int | None = None  # None: the line's own
        self.master_parity: str | None = None

    def hear_master_at(self, baudrate: int | None, parity: str | None = None) -> None:
        """The master now transmits at ``baudrate`` and ``parity`` (None: the line's own).

        A pty server can tell the baud rate but not the parity (Linux drops PARENB from a
        pty's settings); an in-process master can tell both.
        """
        self.master_baudrate = baudrate
        self.master_parity = parity

    @property
    def master_misframed(self) -> bool:
        """Whether the drives cannot read the master's characters (another baud or parity)."""
        baud, parity = self.master_baudrate, self.master_parity
        return (baud is not None and baud != self.baudrate) or (
            parity is not None and self.parity is not None and parity != self.parity
        )

    @property
    def drives(self) -> tuple[SimDrive, ...]:
        """The drives on the line, in the order given."""
        return tuple(drive for drive, _ in self._drives)

    def wire_s(self, length: int) -> float:
        """Seconds ``length`` characters take on the wire."""
        return length * self.char_s

    def write(self, data: bytes) -> None:
        """The master transmits ``data``, starting now (or when its previous bytes are out)."""
        if not data:
            return
        now = self._clock.now()
        start = max(now, self._master_end)
        if start > self._master_end + self.gap_s:
            self._framer.reset()
        burst = _Burst(start, start + self.wire_s(len(data)), bytearray(data), _MASTER,
                       to_master=self.faults.echo)  # fmt: skip
        self._schedule(burst, now)
        self._master_end = burst.end
        if self.master_misframed:  # the drives hear other characters than were sent
            heard = bytearray(self._rng.randrange(1, 256) ^ byte for byte in data)
            self.counters.misframed_bytes += len(data)
            burst = dataclasses.replace(burst, data=heard)
        self._chunks.append((self._fed, now))
        self._fed += len(data)
        # Byte by byte, as the drives hear it: a reply to a telegram early in this burst
        # may collide with (and garble, in place) the burst's later bytes.
        for index in range(len(burst.data)):
            self._framer.feed(bytes(burst.data[index : index + 1]))
            while (piece := self._framer.next_frame()) is not None:
                self._consumed += len(piece.data)
                if isinstance(piece, Skipped):
                    self.counters.skipped_bytes += len(piece.data)
                    continue
                at = self._arrival(self._consumed - len(piece.data))
                self._hear(piece.data, at, start + self.wire_s(index + 1))

    def receive(self) -> bytes:
        """Take every byte that has reached the master by now."""
        now = self._clock.now()
        out = bytearray()
        adapter = self.adapter
        while self._deliveries and self._deliveries[0][0] <= now:
            burst = heapq.heappop(self._deliveries)[2]
            if adapter is None:
                out += burst.data
            else:
                adapter.hold(burst.data, burst.end, self.char_s)
        return bytes(out) if adapter is None else adapter.release(now)

    def next_delivery(self) -> float | None:
        """When the next bytes reach the master, or None if nothing is on its way."""
        wire = self._deliveries[0][0] if self._deliveries else None
        held = self.adapter.next_release() if self.adapter is not None else None
        if wire is None or held is None:
            return held if wire is None else wire
        return min(wire, held)

    # -- requests and replies -------------------------------------------------------------

    def _arrival(self, offset: int) -> float:
        """When the chunk holding stream byte ``offset`` was written."""
        for chunk_offset, at in reversed(self._chunks):
            if chunk_offset <= offset:
                return at
        return self._chunks[0][1]

    def _hear(self, frame: bytes, at: float, end: float) -> None:
        record = Transaction(request_at=at, request_end=end, request_length=len(frame))
        self.transactions.append(record)
        self.counters.requests += 1
        elapsed = end - self.epoch
        line_silent = self.faults.is_silent_period(elapsed)
        for index, (drive, plan) in enumerate(self._drives):
            if line_silent or plan.is_silent_period(elapsed) or self._deaf_until[index] > end:
                continue
            reply = drive.handle(frame, end)
            if reply:
                self._answer(index, drive, plan, reply, record)
        if self._chance(self.faults.noise):
            self._noise(end)

    def _answer(
        self, index: int, drive: SimDrive, plan: FaultPlan, reply: bytes, record: Transaction
    ) -> None:
        rng = self._rng
        if self._chance(plan.silent):
            self._deaf_until[index] = record.request_end + plan.silent_s
            self.counters.silenced += 1
            record.faults.append("silent")
            return
        if self._chance(plan.drop):
            self.counters.dropped += 1
            record.faults.append("drop")
            return
        start = record.request_end + drive.response_delay_s
        if self._chance(plan.late):
            start += plan.late_s
            self.counters.late += 1
            record.faults.append("late")
        data = bytearray(reply)
        if self._chance(plan.corrupt):
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
            self.counters.corrupted += 1
            record.faults.append("corrupt")
        burst = _Burst(start, start + self.wire_s(len(data)), data, drive.address,
                       to_master=True, record=record)  # fmt: skip
        record.address = drive.address
        record.reply_start, record.reply_end, record.reply_length = start, burst.end, len(data)
        self.counters.replies += 1
        self._schedule(burst, self._clock.now())

    def _noise(self, after: float) -> None:
        rng = self._rng
        length = rng.randint(1, self.faults.noise_bytes)
        data = bytearray(rng.randbytes(length))
        # Inside the shortest response delay, so the noise precedes the reply when it fits.
        room = min((drive.response_delay_s for drive, _ in self._drives), default=0.0)
        start = after + rng.random() * max(room - self.wire_s(length), 0.0)
        self.counters.noise_bursts += 1
        self._schedule(_Burst(start, start + self.wire_s(length), data, _NOISE, to_master=True),
                       self._clock.now())  # fmt: skip

    def _chance(self, rate: float) -> bool:
        return rate > 0.0 and self._rng.random() < rate

    # -- the wire -------------------------------------------------------------------------

    def _schedule(self, burst: _Burst, now: float) -> None:
        """Put ``burst`` on the wire, garbling whatever it overlaps, and queue its delivery."""
        self._wire = [other for other in self._wire if other.end > now]
        for other in self._wire:
            if other.start < burst.end and burst.start < other.end:
                self._garble(other, burst.start, burst.end)
                self._garble(burst, other.start, other.end)
                self.counters.collisions += 1
                for record in (other.record, burst.record):
                    if record is not None and "collision" not in record.faults:
                        record.faults.append("collision")
        self._wire.append(burst)
        if burst.to_master:
            self._sequence += 1
            heapq.heappush(self._deliveries, (burst.end, self._sequence, burst))

    def _garble(self, burst: _Burst, start: float, end: float) -> None:
        """Replace the characters of ``burst`` that overlap ``start``…``end`` with garbage."""
        first = max(0, math.floor((start - burst.start) / self.char_s))
        last = min(len(burst.data), math.ceil((end - burst.start) / self.char_s))
        for i in range(first, last):
            burst.data[i] ^= self._rng.randrange(1, 256)
