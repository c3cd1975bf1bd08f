"""The wire discipline of a half-duplex line: one exchange at a time, done right.

:class:`Link` carries one :class:`~fcmaster.protocol.codec.Exchange` at a time over a
transport: it waits out the pause the protocol asks after the previous reply, drops stale
input, writes the request as one burst, and reads until the codec's framer yields a frame
that answers the request or the deadline passes. Frames from another address, malformed
frames and noise are counted and the read goes on. After a timeout it lets the line drain
for a reply's length, so a late reply is discarded before the next request instead of
being taken for its answer. An inter-character gap gives up an unfinished frame.

The deadline for a reply follows the line (:mod:`~fcmaster.bus.answer_times`) for polls and
probes; a command's exchange keeps the plan's fixed deadline, since a drive may take longer
over some (storing a parameter) and a late answer must not turn a command that was carried
out into a timeout. ``timeout_s`` in the config overrides both.

A reply is taken in the transport's reader callback (:meth:`Link.watch`), once whole, and
:meth:`Link.send_now` writes from a callback: a line's runner chains exchanges that way
(:mod:`~fcmaster.bus.runner`). :meth:`Link.send` and :meth:`Link.receive` are the same
steps for a task, and receive waits on the same watch: every transport a line runs on has
these callback powers (:class:`~fcmaster.transport.pipe.Framing`), so there is one way a
reply is read, on a real port and in the virtual-time tests alike.

The BusMaster's runner drives a Link from its planner; the commissioning commands (scan,
status, read, write, control) drive one directly, as a task.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from functools import partial

from fcmaster.bus.answer_times import AnswerTimes
from fcmaster.bus.frame_log import RX, TX, FrameLog
from fcmaster.bus.plan import LinePlan
from fcmaster.bus.stats import LineStats
from fcmaster.clock import Clock
from fcmaster.errors import MalformedReply, ProtocolError, UnexpectedReply
from fcmaster.protocol.codec import DriveCodec, Exchange, Reply
from fcmaster.protocol.framing import Frame, Framer, Skipped, SkipReason
from fcmaster.transport.pipe import Transport

RECORDED = 32  # frames and events the flight recorder keeps
PARSED_LIMIT = 4096  # requests whose last reply is kept (see Link._parse)

# A transport that feeds the framer in its reader callback (SerialTransport.watch_frame).
WatchFrame = Callable[
    [Framer, float, float, Callable[[Frame | Skipped | None], None]], Frame | Skipped | None
]
# What a watch ends with: the reply (None: none came), or what ended the read.
Answered = Callable[[Reply | None, Exception | None], None]


class Link:
    """One exchange at a time on one transport."""

    def __init__(
        self,
        plan: LinePlan,
        *,
        codec: DriveCodec,
        transport: Transport,
        clock: Clock,
        stats: LineStats | None = None,
    ) -> None:
        self.plan = plan
        self.codec = codec
        self.transport = transport
        self.clock = clock
        self.stats = stats or LineStats()
        # The flight recorder: the last RECORDED frames and events, in two rings written in
        # place, so a transaction leaves no object of its own behind (not even a tuple).
        self._kinds: list[str] = [""] * RECORDED
        self._data: list[bytes] = [b""] * RECORDED
        self._recorded = 0
        self.frames = FrameLog(clock.wall)  # the frames with their times, for captures
        self._parsed: dict[bytes, tuple[Exchange, bytes, Reply]] = {}  # see _parse
        self.pause_s = plan.pause_s if plan.pause_s is not None else codec.min_pause_s(plan.char_s)
        self._plan_gap_s = plan.gap_s
        self.written_at = 0.0  # when the last request was written
        self.ready_at = 0.0  # when the next request may go (pause, drain or broadcast wait)
        self.replied_at = 0.0  # when the last byte of the last reply arrived
        self._arrived = 0.0
        self._framer = codec.new_framer()
        # Every line's transport frames as bytes arrive and writes at once (a serial port,
        # the simulator's line, the tests' scripted line): a whole exchange runs in
        # callbacks, see watch and send_now, and a task's receive waits on the same watch.
        framing = transport.framing
        if framing is None:
            raise TypeError(f"{type(transport).__name__} cannot frame in its reader callback")
        self._watch_frame: WatchFrame = framing.watch_frame
        self._write_now: Callable[[bytes], None] = framing.write_now
        self._unwatch: Callable[[], None] = framing.unwatch
        self._check_open: Callable[[], None] = framing.check_open
        self._exchange: Exchange | None = None  # what the watch waits for, until when
        self._deadline = 0.0
        self._gap = 0.0
        self._done: Answered | None = None
        self._replied_at: float | None = None
        self._answer_times = AnswerTimes(plan)  # how long replies take beyond their wire time
        self._timed = self._answer_times.timed
        self._missed: tuple[float, float] | None = None  # the last request timed out: when, wire
        self._suspect: tuple[float, float] | None = None  # the one before, its reply not seen

    @property
    def gap_s(self) -> float:
        """An inter-character gap this long ends an unfinished frame.

        The plan's, widened by a USB adapter's latency timer where the transport knows it
        (``SerialTransport.adapter``, read from sysfs when the port opened): the adapter
        sends what it holds at each tick, so a reply that spans a tick reaches the host in
        two chunks up to a tick apart, and a gap shorter than that would cut it in two (its
        halves counted as noise, the poll as a timeout). The plan's gap still follows.
        """
        adapter = self.transport.adapter
        latency_ms = adapter.latency_ms if adapter is not None else None
        if not latency_ms:
            return self._plan_gap_s
        return latency_ms / 1000 + self._plan_gap_s

    def deadline_s(self, request_length: int, reply_length: int) -> float:
        """Seconds from writing a request to giving up on its reply (see answer_times)."""
        return self._answer_times.deadline_s(request_length, reply_length)

    async def send(self, exchange: Exchange) -> None:
        """Wait for the line to be free, drop stale input, and write the request."""
        ready_at = self.ready_at
        if ready_at > self.clock.now():
            await self.clock.sleep_until(ready_at)
            written_at = self._writing(exchange)
            self.stats.wakeup_lateness.observe(written_at - ready_at)
        else:
            written_at = self._writing(exchange)
        await self.transport.write(exchange.request)
        self._written(exchange, written_at)

    def send_now(self, exchange: Exchange) -> None:
        """:meth:`send` from a callback, once :attr:`ready_at` has passed."""
        written_at = self._writing(exchange)
        self._write_now(exchange.request)
        self._written(exchange, written_at)

    def _writing(self, exchange: Exchange) -> float:
        """Drop stale input before a request; when it is being written."""
        stats = self.stats
        stale = self.transport.discard_input()
        if stale:
            stats.late_bytes += len(stale)
            self._record("discarded", stale)
            self.frames.add(RX, stale, self.transport.received_at)
            if self._missed is not None:
                # Most likely the reply that missed its deadline: how late it really was
                # counts too, so the deadline widens instead of missing replies again.
                sent_at, wire = self._missed
                self._timed(self.transport.received_at - sent_at - wire)
                self._missed = None
        # A miss not heard of yet may still come, during this exchange: see _drain.
        self._suspect, self._missed = self._missed, None
        written_at = self.written_at = self.clock.now()
        if self._replied_at is not None:
            stats.turnaround.observe(max(0.0, written_at - self._replied_at - self.pause_s))
            self._replied_at = None
        return written_at

    def _written(self, exchange: Exchange, written_at: float) -> None:
        stats = self.stats
        self._record("tx", exchange.request)
        self.frames.add(TX, exchange.request, written_at)
        stats.requests += 1
        if not exchange.expects_reply:
            # Broadcasts and resets get no answer: give the drives time to act on them.
            stats.broadcasts += 1
            self.ready_at = (
                written_at
                + self.plan.wire_s(len(exchange.request))
                + self.plan.response_delay_s
                + self.pause_s
            )
            stats.busy_s += self.ready_at - written_at

    def reply_deadline(self, exchange: Exchange, *, adaptive: bool = True) -> float:
        """When to give up on the reply to the request just sent.

        ``adaptive``: the deadline follows the line; otherwise it is the plan's fixed one.
        """
        request_length, reply_length = len(exchange.request), exchange.reply_length
        if adaptive:
            return self.written_at + self.deadline_s(request_length, reply_length)
        return self.written_at + self.plan.reply_timeout(request_length, reply_length)

    async def receive(self, exchange: Exchange, *, adaptive: bool = True) -> Reply | None:
        """The reply to the request just sent, or None when none came before the deadline.

        ``adaptive``: the deadline follows the line; otherwise it is the plan's fixed one.
        """
        deadline = self.reply_deadline(exchange, adaptive=adaptive)
        waiter: asyncio.Future[Reply | None] = asyncio.get_running_loop().create_future()
        self.watch(exchange, deadline, partial(_settle, waiter))
        try:
            reply = await waiter
        finally:
            self.unwatch()
        self.received(exchange, reply)
        return reply

    def received(self, exchange: Exchange, reply: Reply | None) -> None:
        """Account for the end of the exchange just sent: ``reply``, or None for a timeout."""
        clock, stats, plan = self.clock, self.stats, self.plan
        written_at = self.written_at
        wire = plan.wire_s(len(exchange.request) + exchange.reply_length)
        if reply is None:
            stats.timeouts += 1
            self._record("timeout", b"")
            self._missed = (written_at, wire)
            # Let a late reply finish arriving, so it is discarded, not misattributed.
            self.ready_at = clock.now() + plan.wire_s(exchange.reply_length) + self.gap_s
        else:
            # The pause runs from the reply's arrival, so decoding it, the planner's update
            # and the next request's encoding all happen inside the pause.
            arrived = self.replied_at = max(self._arrived, written_at)
            stats.replies += 1
            stats.latency.observe(arrived - written_at)
            self._timed(arrived - written_at - wire)
            self._replied_at = arrived
            self.ready_at = arrived + self.pause_s
        stats.busy_s += self.ready_at - written_at

    async def transact(self, exchange: Exchange) -> Reply | None:
        """Send ``exchange`` and return its reply (None: no reply expected, or none came)."""
        await self.send(exchange)
        if not exchange.expects_reply:
            return None
        return await self.receive(exchange)

    def watch(self, exchange: Exchange, deadline: float, done: Answered) -> None:
        """Read the reply to the request just sent in the transport's reader callback.

        ``done`` is called once: with the reply, with None when none came before
        ``deadline``, or with the exception that ended the read (the port was lost). The
        chunks of a reply are fed to the framer as they arrive and ``done`` is called when
        it is whole: no task wakes for it.
        """
        self._exchange, self._deadline, self._done = exchange, deadline, done
        self._gap = self.gap_s
        piece = self._watch_frame(self._framer, deadline, self._gap, self._on_piece)
        if piece is not None:  # whole already (None: done will be called later)
            self._on_piece(piece)

    def unwatch(self) -> None:
        """Stop a :meth:`watch` (``done`` will not be called)."""
        if self._done is not None:
            self._done = None
            self._unwatch()

    def _on_piece(self, piece: Frame | Skipped | None) -> None:
        done = self._done
        if done is None:
            return
        exchange, framer, transport = self._exchange, self._framer, self.transport
        assert exchange is not None  # set with _done
        try:
            while True:
                if piece is None:
                    self._check_open()  # the port may have been lost meanwhile
                    # A gap (or the deadline): an unfinished frame will not be completed.
                    framer.reset()
                    reply = self._drain(exchange)
                    if reply is None:
                        late = self.clock.now() - self._deadline
                        if late < 0:
                            piece = self._watch_frame(
                                framer, self._deadline, self._gap, self._on_piece
                            )
                            if piece is None:
                                return  # wait on
                            continue
                        self.stats.wakeup_lateness.observe(late)
                else:
                    self._arrived = transport.received_at
                    reply = self._take(exchange, piece)
                    if reply is None:
                        reply = self._drain(exchange)
                    if reply is None:
                        piece = self._watch_frame(framer, self._deadline, self._gap, self._on_piece)
                        if piece is None:
                            return  # wait on
                        continue
                break
        except Exception as exc:  # the port was lost: the reader hears of it
            self._done = None
            done(None, exc)
            return
        self._done = None
        done(reply, None)

    def _drain(self, exchange: Exchange) -> Reply | None:
        """Hand the framer's pieces to the codec until one answers ``exchange``."""
        framer = self._framer
        while (piece := framer.next_frame()) is not None:
            reply = self._take(exchange, piece)
            if reply is not None:
                return reply
        return None

    def _take(self, exchange: Exchange, piece: Frame | Skipped) -> Reply | None:
        """One piece: the reply to ``exchange``, or counted (and None)."""
        self.frames.add(RX, piece.data, self._arrived)
        stats = self.stats
        if isinstance(piece, Frame):
            try:
                reply = self._parse(exchange, piece.data)
            except UnexpectedReply:
                stats.unexpected += 1
                self._record("unexpected", piece.data)
                if self._suspect is not None:
                    # Likely the previous request's reply, later than even the drain
                    # allowed for (a device server's network, a busy host): count how
                    # late, or every reply would go on missing its deadline by one.
                    sent_at, wire = self._suspect
                    self._timed(self.transport.received_at - sent_at - wire)
                    self._suspect = None
                return None
            except (MalformedReply, ProtocolError):
                stats.malformed += 1
                self._record("malformed", piece.data)
                return None
            self._record("rx", piece.data)
            self._discard_rest()
            return reply
        stats.noise_bytes += len(piece.data)
        if piece.reason is SkipReason.CHECKSUM:
            stats.checksum_errors += 1
        self._record(str(piece.reason), piece.data)
        return None

    def _parse(self, exchange: Exchange, frame: bytes) -> Reply:
        """The codec's reply to ``frame``; the same one as last time when nothing changed.

        A drive polled with the same request mostly answers with the same bytes (its status
        and the value read unchanged). Parsing is a pure function of the exchange and the
        frame, so the Reply from last time is the answer again, and the layers above can
        tell an unchanged reply by its identity. Keyed by the request's bytes (whose hash
        Python keeps), checked against the exchange itself; forgotten past
        :data:`PARSED_LIMIT` requests, like the polls' cache.
        """
        parsed = self._parsed
        last = parsed.get(exchange.request)
        if last is not None and last[1] == frame and (last[0] is exchange or last[0] == exchange):
            return last[2]
        reply = self.codec.parse(exchange, frame)
        if len(parsed) >= PARSED_LIMIT:
            parsed.clear()
        parsed[exchange.request] = (exchange, frame, reply)
        return reply

    def _discard_rest(self) -> None:
        """Bytes after the reply are late or noise: counted, never taken for a reply."""
        framer = self._framer
        if not framer.buffered:  # mostly: the reply came alone
            return
        framer.reset()
        while (piece := framer.next_frame()) is not None:
            self.stats.late_bytes += len(piece.data)
            self.frames.add(RX, piece.data, self._arrived)

    def _record(self, kind: str, data: bytes) -> None:
        at = self._recorded % RECORDED
        self._kinds[at], self._data[at] = kind, data
        self._recorded += 1

    def recent_frames(self) -> list[str]:
        """The last frames and events on the line, oldest first, for warnings and errors."""
        kinds, data, recorded = self._kinds, self._data, self._recorded
        return [
            f"{kinds[i % RECORDED]} {data[i % RECORDED].hex(' ')}".rstrip()
            for i in range(max(0, recorded - RECORDED), recorded)
        ]


def _settle(
    waiter: asyncio.Future[Reply | None], reply: Reply | None, error: Exception | None
) -> None:
    if waiter.done():
        return
    if error is not None:
        waiter.set_exception(error)
    else:
        waiter.set_result(reply)
