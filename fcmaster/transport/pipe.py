"""The byte pipe under a BusMaster: a serial port, a TCP serial server, or the simulator.

A transport moves bytes and nothing else: no framing, no retries, no timing policy. It is a
``typing.Protocol`` so the simulator's in-process line and test doubles meet it without
inheriting from anything.

A transport may offer more (:class:`~fcmaster.transport.serial.SerialTransport` does): a
``write_now`` that takes the bytes from a plain callback, and a ``watch_frame`` that feeds
a framer in its reader callback and calls back once a piece is whole (with ``unwatch`` and
``check_open``). The :class:`~fcmaster.bus.link.Link` then reads replies without a task
waking per chunk, and the BusMaster carries its polls in callbacks
(:mod:`fcmaster.bus.steady`). Without them the same rules run in the master's task.
"""

from __future__ import annotations

from typing import Protocol


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
