"""The simulator in-process: a Transport onto a SimLine, and ``sim://NAME`` lookup.

:class:`SimTransport` meets :class:`fcmaster.transport.pipe.Transport`, so a BusMaster
talks to simulated drives exactly as to a serial port, with no pseudo-terminal in between.
All waiting goes through the injected clock: with a virtual clock a whole bus runs in
virtual time; with :class:`~fcmaster.clock.MonotonicClock` it takes as long as the wire.
"""

from __future__ import annotations

from fcmaster.clock import Clock
from fcmaster.errors import PortError, ReplyTimeout, UsageError
from fcmaster.sim.line import SimLine

SIM_SCHEME = "sim://"


class SimTransport:
    """A :class:`~fcmaster.transport.pipe.Transport` on a simulated line."""

    def __init__(self, line: SimLine, clock: Clock, *, port: str = "sim://") -> None:
        """Talk to ``line``, waiting on ``clock`` (which must be the clock the line reads)."""
        self.port = port
        self.line = line
        self._clock = clock
        self._open = False
        self.received_at = 0.0  # the simulated line hands bytes over as they arrive

    async def open(self) -> None:
        """Connect; a simulated line is always there."""
        self._open = True

    async def close(self) -> None:
        """Disconnect; safe when not open."""
        self._open = False

    async def write(self, data: bytes) -> None:
        """Put ``data`` on the line now (the call returns before the bytes are out)."""
        self._check_open()
        self.line.write(data)

    async def read(self, deadline: float) -> bytes:
        """The bytes that reached the master, waiting until at least one has or ``deadline``."""
        self._check_open()
        line, clock = self.line, self._clock
        while True:
            data = line.receive()
            if data:
                self.received_at = clock.now()
                return data
            if clock.now() >= deadline:
                raise ReplyTimeout(f"nothing from {self.port} before the deadline", bus=self.port)
            due = line.next_delivery()
            await clock.sleep_until(deadline if due is None else min(due, deadline))

    def discard_input(self) -> bytes:
        """Drop and return what reached the master and was not read."""
        return self.line.receive()

    def _check_open(self) -> None:
        if not self._open:
            raise PortError(f"{self.port} is not open", bus=self.port)


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
