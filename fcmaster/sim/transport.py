"""The simulator in-process: a Transport onto a SimLine, and ``sim://NAME`` lookup.

:class:`SimTransport` meets :class:`fcmaster.transport.pipe.Transport`, so a BusMaster
talks to simulated drives exactly as to a serial port, with no pseudo-terminal in between.
All waiting goes through the injected clock: with a virtual clock a whole bus runs in
virtual time; with :class:`~fcmaster.clock.MonotonicClock` it takes as long as the wire.
"""

from __future__ import annotations

import asyncio

from fcmaster.clock import Cancellable, Clock
from fcmaster.errors import PortError, ReplyTimeout, UsageError
from fcmaster.protocol.framing import Framer
from fcmaster.sim.line import SimLine
from fcmaster.transport.receiver import Handler, Piece, Receiver

SIM_SCHEME = "sim://"


class SimTransport:
    """A :class:`~fcmaster.transport.pipe.Transport` on a simulated line.

    What the line delivers to the master is pumped, at the time it arrives, into the serial
    transport's own :class:`~fcmaster.transport.receiver.Receiver`, so the transport has a
    serial port's callback powers (:attr:`framing`) and the master runs on a simulated line
    exactly the path it runs on a real port.
    """

    def __init__(self, line: SimLine, clock: Clock, *, port: str = "sim://") -> None:
        """Talk to ``line``, waiting on ``clock`` (which must be the clock the line reads)."""
        self.port = port
        self.line = line
        self._clock = clock
        self._open = False
        self._receiver = Receiver(clock)
        self._pump: Cancellable | None = None  # the timer for the line's next delivery
        self._pump_at = 0.0

    @property
    def received_at(self) -> float:
        """When the bytes the master last got reached it."""
        return self._receiver.received_at

    async def open(self) -> None:
        """Connect; a simulated line is always there."""
        self._open = True
        self._receiver.lost = None

    async def close(self) -> None:
        """Disconnect; safe when not open."""
        self._open = False
        if self._pump is not None:
            self._pump.cancel()
            self._pump = None
        self._receiver.unwatch()
        self._receiver.buffer.clear()

    async def write(self, data: bytes) -> None:
        """Put ``data`` on the line now (the call returns before the bytes are out)."""
        self.write_now(data)

    def write_now(self, data: bytes) -> None:
        """:meth:`write` from a callback."""
        self.check_open()
        self.line.write(data)
        self._schedule_pump()

    async def read(self, deadline: float) -> bytes:
        """The bytes that reached the master, waiting until at least one has or ``deadline``."""
        self.check_open()
        self._deliver()
        receiver = self._receiver
        if not receiver.buffer:
            await receiver.wait_bytes(deadline)
            self.check_open()
            if not receiver.buffer:
                raise ReplyTimeout(f"nothing from {self.port} before the deadline", bus=self.port)
        return self._take()

    def watch_frame(self, framer: Framer, deadline: float, gap_s: float, handler: Handler) -> Piece:
        """Feed ``framer`` as the line delivers; see :class:`~fcmaster.transport.pipe.Framing`."""
        self._deliver()
        return self._receiver.watch(framer, deadline, gap_s, handler)

    def unwatch(self) -> None:
        """Stop a :meth:`watch_frame`."""
        self._receiver.unwatch()

    def check_open(self) -> None:
        """PortError when the transport is not open."""
        if not self._open:
            raise PortError(f"{self.port} is not open", bus=self.port)

    def discard_input(self) -> bytes:
        """Drop and return what reached the master and was not read."""
        self._deliver()
        return self._take()

    @property
    def framing(self) -> SimTransport:
        """This transport frames in callbacks, as a serial port does."""
        return self

    adapter = None  # no USB adapter: the simulated line's own adapter model is in the line

    async def appeared(self) -> None:
        """Never: a simulated line has no device node to come back."""
        await asyncio.Event().wait()

    def _take(self) -> bytes:
        buffer = self._receiver.buffer
        data = bytes(buffer)
        buffer.clear()
        return data

    def _deliver(self, at: float | None = None) -> None:
        """Hand the receiver what has reached the master by now (which arrived ``at``)."""
        data = self.line.receive()
        if data:
            self._receiver.arrived(data, self._clock.now() if at is None else at)

    def _schedule_pump(self) -> None:
        due = self.line.next_delivery()
        if due is None or (self._pump is not None and self._pump_at <= due):
            return
        if self._pump is not None:
            self._pump.cancel()
        self._pump_at = due
        # A plain timer, not a spun one: timers that fall due together run in the order of
        # their times, so a delivery due before a reply's deadline is always handed over
        # before the deadline fires, however late the loop gets to them. Stamped with the
        # time the bytes arrived, not the time the timer ran.
        self._pump = self._clock.timer_at(due, self._on_pump)

    def _on_pump(self) -> None:
        self._pump = None
        if self._open:
            self._deliver(min(self._pump_at, self._clock.now()))
            self._schedule_pump()


def sim_name(port: str) -> str | None:
    """``"sim://line1"`` → ``"line1"``; None for a port that is not simulated."""
    return port[len(SIM_SCHEME) :] if port.startswith(SIM_SCHEME) else None


class SimRegistry:
    """Simulated lines by name, so a configured ``sim://NAME`` port can be opened."""

    def __init__(self) -> None:
        self._lines: dict[str, SimLine] = {}

    def add(self, name: str, line: SimLine) -> None:
        """Make ``line`` reachable as ``sim://name``."""
        if not name or "/" in name:
            raise UsageError(f"simulated line name {name!r} must be non-empty, without '/'")
        if name in self._lines:
            raise UsageError(f"a simulated line is already called {name!r}")
        self._lines[name] = line

    def line(self, name: str) -> SimLine:
        """The line called ``name``; PortError if there is none."""
        try:
            return self._lines[name]
        except KeyError:
            raise PortError(f"no simulated line {name!r}", bus=name) from None

    def transport(self, port: str, clock: Clock) -> SimTransport:
        """A transport for a ``sim://NAME`` port; PortError if no such line exists."""
        name = sim_name(port)
        if name is None:
            raise UsageError(f"{port!r} is not a sim:// port")
        return SimTransport(self.line(name), clock, port=port)

    @property
    def names(self) -> tuple[str, ...]:
        """The names of the registered lines."""
        return tuple(self._lines)
