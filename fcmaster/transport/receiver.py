"""What a serial transport receives, and the one reader waiting for it.

Bytes arrive in the event loop's reader callback (or, from a reader thread, in a callback
the thread schedules). Nobody waiting: they are kept in a buffer. A reader waiting for bytes
(:meth:`Receiver.wait_bytes`) is woken by the first chunk. A reader that hands over its
framer (:meth:`Receiver.watch`) is not woken per chunk: the chunks are fed to the framer
right here, and its handler is called once, when the framer holds a whole piece (a frame,
or bytes it skipped), when an inter-character gap has passed after an unfinished frame, or
at the deadline. A reply then costs one call however the adapter split it, and the handler
may be a plain function: a line's runner decodes the reply and schedules
the next request from it without a task ever waking.

Times are the transport's :class:`~fcmaster.clock.Clock`'s, and so are the timers (its
``timer_at``): on the real clock they go on the event loop as delays from the clock's
present, so the clock need not share the loop's timebase; on a virtual clock they fire in
virtual time, and the same reader runs in the virtual-time tests.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from functools import partial

from fcmaster.clock import Cancellable, Clock
from fcmaster.protocol.framing import Frame, Framer, Skipped

Piece = Frame | Skipped | None
Handler = Callable[[Piece], None]


class Receiver(asyncio.Protocol):
    """Collects received bytes and hands them to the one reader waiting for them."""

    __slots__ = (
        "_deadline",
        "_deadline_timer",
        "_gap_due",
        "_gap_timer",
        "_handler",
        "_now",
        "_timer_at",
        "buffer",
        "framer",
        "gap_s",
        "lost",
        "received_at",
        "waiter",
    )

    def __init__(self, clock: Clock) -> None:
        self._now = clock.now
        self._timer_at = clock.timer_at
        self.buffer = bytearray()
        self.waiter: asyncio.Future[None] | None = None  # a reader of bytes, while it waits
        self.lost: Exception | None = None
        self.received_at = 0.0
        self.framer: Framer | None = None  # the watching reader's, while it watches
        self.gap_s = 0.0
        self._handler: Handler | None = None
        self._gap_due = 0.0  # when the gap timer is set to look
        self._gap_timer: Cancellable | None = None
        self._deadline = 0.0  # the watching reader's
        self._deadline_timer: Cancellable | None = None

    # -- from the port -----------------------------------------------------------------

    def data_received(self, data: bytes) -> None:
        """``data`` was read on the loop just now."""
        self.arrived(data, self._now())

    def arrived(self, data: bytes, at: float) -> None:
        """``data`` arrived at clock time ``at`` (seen first in another thread)."""
        self.received_at = at
        framer = self.framer
        if framer is None:
            self.buffer += data
            waiter = self.waiter
            if waiter is not None and not waiter.done():
                waiter.set_result(None)
            return
        framer.feed(data)
        piece = framer.next_frame()
        if piece is not None:
            self._hand(piece)
        elif self.gap_s and framer.buffered:
            # An unfinished frame: look again one gap after its last byte (_look_at_gap,
            # written out here: this runs for every chunk).
            due = at + self.gap_s
            if self._gap_timer is None or self._gap_due > due:
                if self._gap_timer is not None:
                    self._gap_timer.cancel()
                self._gap_due = due
                self._gap_timer = self._timer_at(due, self._on_gap)

    def connection_lost(self, exc: Exception | None) -> None:
        """The port is gone: wake whoever waits."""
        self.lost = exc or ConnectionError("port closed")
        waiter = self.waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)
        if self._handler is not None:
            self._hand(None)

    # -- readers -----------------------------------------------------------------------

    async def wait_bytes(self, deadline: float) -> None:
        """Return when bytes are buffered, the port is lost, or ``deadline`` passed."""
        waiter: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self.waiter = waiter
        timer = self._timer_at(deadline, partial(_expire, waiter))
        try:
            await waiter
        finally:
            timer.cancel()
            self.waiter = None

    def watch(self, framer: Framer, deadline: float, gap_s: float, handler: Handler) -> Piece:
        """Feed received bytes to ``framer``; the next piece it cuts, if one is whole now.

        Otherwise (None) ``handler`` is called once, later: with the piece, or with None
        when ``deadline`` or a gap of ``gap_s`` after an unfinished frame has passed, or
        the port was lost (:attr:`lost`). The caller tells these apart by the time.
        """
        if self.buffer:
            framer.feed(bytes(self.buffer))
            self.buffer.clear()
        if framer.buffered:  # mostly not: the last reply was taken whole
            piece = framer.next_frame()
            if piece is not None:
                return piece
        if self.lost is not None:
            handler(None)
            return None
        self.framer, self.gap_s, self._handler = framer, gap_s, handler
        self._deadline = deadline
        # Set for this read and cancelled when it ends: a timer kept for the next read
        # would fire during it, a wake-up for nothing (a cancelled one never wakes the loop).
        self._set_deadline_timer(deadline)
        if gap_s and framer.buffered:
            # A frame begun in an earlier read: the gap runs from its last bytes, on the gap
            # timer, which follows the chunks that arrive meanwhile (the deadline's would not).
            self._look_at_gap(self.received_at + gap_s)
        return None

    def unwatch(self) -> None:
        """Stop watching (the reader gave up); later bytes wait in the buffer."""
        self.framer = self._handler = None
        for timer in (self._deadline_timer, self._gap_timer):
            if timer is not None:
                timer.cancel()
        self._deadline_timer = self._gap_timer = None

    def _set_deadline_timer(self, due: float) -> None:
        if self._deadline_timer is not None:
            self._deadline_timer.cancel()
        self._deadline_timer = self._timer_at(due, self._on_deadline)

    def _on_deadline(self) -> None:
        self._deadline_timer = None
        if self._deadline > self._now():  # the loop woke a hair early
            self._set_deadline_timer(self._deadline)
            return
        self._hand(None)

    def _look_at_gap(self, due: float) -> None:
        """An unfinished frame: look again at ``due``, one gap after its last byte.

        The timer is moved only when it fires (see :meth:`_on_gap`), not for every chunk.
        """
        if self._gap_timer is None or self._gap_due > due:
            if self._gap_timer is not None:
                self._gap_timer.cancel()
            self._gap_due = due
            self._gap_timer = self._timer_at(due, self._on_gap)

    def _on_gap(self) -> None:
        """The gap timer fired: hand over unless bytes came since it was set."""
        self._gap_timer = None
        due = self.received_at + self.gap_s
        if due > self._now() and self._handler is not None:
            self._gap_due = due
            self._gap_timer = self._timer_at(due, self._on_gap)
            return
        self._hand(None)

    def _hand(self, piece: Piece) -> None:
        handler = self._handler
        self.unwatch()
        if handler is not None:
            handler(piece)


def _expire(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)
