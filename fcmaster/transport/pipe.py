"""The byte pipe under a BusMaster: a serial port, a TCP serial server, or the simulator.

A transport moves bytes and nothing else: no framing, no retries, no timing policy. It is a
``typing.Protocol`` so the simulator's in-process line and test doubles meet it without
inheriting from anything.

What a transport can do beyond moving bytes is part of its type, never guessed at: its
:attr:`Transport.framing` (the powers of :class:`Framing`: write from a plain callback, and
feed a framer in its reader callback, calling back once a piece is whole), the USB
:attr:`Transport.adapter` behind it, and :meth:`Transport.appeared` for a device node that
comes back. With framing, the :class:`~fcmaster.bus.link.Link` reads replies without a task
waking per chunk, and the BusMaster carries every step in callbacks
(:mod:`fcmaster.bus.runner`) — on a real port and on the virtual-time tests' scripted line
alike. A line's transport must have it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from fcmaster.transport.receiver import Handler, Piece

if TYPE_CHECKING:
    from fcmaster.protocol.framing import Framer
    from fcmaster.transport.usb import Adapter


class Framing(Protocol):
    """A transport's callback powers: what lets a line run without a task waking."""

    def write_now(self, data: bytes) -> None:
        """Hand ``data`` to the port from a plain callback; PortError if it is gone."""

    def watch_frame(self, framer: Framer, deadline: float, gap_s: float, handler: Handler) -> Piece:
        """Feed ``framer`` as bytes arrive; ``handler`` gets the next whole piece.

        A piece whole already is returned and ``handler`` is not called; otherwise it is
        called once, later: with the piece, or None at ``deadline``, after a gap of
        ``gap_s`` behind an unfinished frame, or when the port was lost.
        """

    def unwatch(self) -> None:
        """Stop a :meth:`watch_frame` (its handler is not called)."""

    def check_open(self) -> None:
        """Raise PortError if the port was lost."""


class Transport(Protocol):
    """An async byte pipe to one RS-485 line."""

    async def open(self) -> None:
        """Open the port; raise PortError if it cannot be opened."""

    async def close(self) -> None:
        """Close the port; safe to call when it is not open."""

    async def write(self, data: bytes) -> None:
        """Send ``data`` as one burst; raise PortError if the port is gone."""

    async def read(self, deadline: float) -> bytes:
        """Return the bytes received so far, waiting for at least one until ``deadline``.

        ``deadline`` is on the injected clock's timebase. Raises ReplyTimeout when nothing
        arrived by then, PortError when the port is gone.
        """

    @property
    def received_at(self) -> float:
        """When the bytes the last ``read`` returned arrived, on the injected clock's timebase.

        Noted where the bytes are first seen (a serial port's reader callback), not when the
        reader gets to them: the pause after a reply counts from its arrival, and the
        event-loop pass in between is no part of it.
        """

    def discard_input(self) -> bytes:
        """Drop and return whatever was received and not read yet (late replies, noise)."""

    @property
    def framing(self) -> Framing | None:
        """The transport's callback powers; None where replies can only be awaited."""

    @property
    def adapter(self) -> Adapter | None:
        """The USB adapter behind a local port, once open (its latency timer); else None."""

    async def appeared(self) -> None:
        """Return when the port's vanished device node is back; never, where it has none."""
