"""Local-echo suppression for two-wire adapters that hear their own transmission."""

from __future__ import annotations

from functools import partial

from fcmaster.errors import PortError, ReplyTimeout
from fcmaster.protocol.framing import Frame, Framer, Skipped
from fcmaster.transport.pipe import Framing, Transport
from fcmaster.transport.receiver import Handler, Piece
from fcmaster.transport.usb import Adapter


class EchoCancellingTransport:
    """Wraps a transport and removes the echo of each request from what is received.

    The echo comes first and byte for byte. Bytes that match it so far are held back until
    the whole echo is in, and only then dropped; as soon as a byte differs (a collision, or
    an adapter that did not echo after all) the held bytes and the rest are passed on
    untouched, so a reply that merely starts like the request (FC: STX, LGE, ADR) is never
    eaten. A gap (or a read's deadline) with an echo cut short hands the held bytes on: an
    echo cut short is no echo.

    The same rule serves both ways of receiving: :meth:`read`, and the reader callback's
    framing (:attr:`framing`), where the reader's framer is fed through an
    :class:`_EchoFilter` in front of it.
    """

    __slots__ = ("_expect", "_filter", "_held", "_inner")

    def __init__(self, inner: Transport) -> None:
        self._inner = inner
        self._expect = b""  # the echo still awaited, whole
        self._held = b""  # bytes received that match the start of ``_expect``
        self._filter: _EchoFilter | None = None

    async def open(self) -> None:
        """Open the wrapped transport."""
        await self._inner.open()

    async def close(self) -> None:
        """Close the wrapped transport."""
        await self._inner.close()

    async def appeared(self) -> None:
        """As the wrapped transport's (a device node that reappears)."""
        await self._inner.appeared()

    async def write(self, data: bytes) -> None:
        """Write, and expect ``data`` back first."""
        self._expect, self._held = data, b""
        await self._inner.write(data)

    def write_now(self, data: bytes) -> None:
        """:meth:`write` from a callback."""
        self._expect, self._held = data, b""
        self._inner_framing().write_now(data)

    async def read(self, deadline: float) -> bytes:
        """Read past the echo."""
        while True:
            cut_short = False
            try:
                data = await self._inner.read(deadline)
            except ReplyTimeout:
                if not self._held:
                    raise
                data, cut_short = b"", True
            passed = self.passed(data, cut_short=cut_short)
            if passed:
                return passed

    def passed(self, data: bytes, *, cut_short: bool = False) -> bytes:
        """What of ``data`` (received after the bytes held) is no echo: b"" while one may be.

        ``cut_short``: nothing more will come for now (a gap, a deadline), so bytes held as
        the start of an echo are handed on.
        """
        if not self._expect:
            return data
        data, self._held = self._held + data, b""
        expect = self._expect
        if data[: len(expect)] == expect:  # the whole echo: drop it
            self._expect = b""
            return data[len(expect) :]
        if expect.startswith(data) and not cut_short:  # an echo so far: wait for the rest
            self._held = data
            return b""
        self._expect = b""  # diverged, or cut short: no echo, hand everything back
        return data

    @property
    def held(self) -> int:
        """Bytes held back as the start of an echo."""
        return len(self._held)

    def watch_frame(self, framer: Framer, deadline: float, gap_s: float, handler: Handler) -> Piece:
        """The wrapped transport's, with the echo taken off before ``framer`` sees it."""
        echo_filter = self._filter
        if echo_filter is None or echo_filter.inner is not framer:
            echo_filter = self._filter = _EchoFilter(self, framer)
        handed = partial(self._handed, framer, handler)
        return self._inner_framing().watch_frame(echo_filter, deadline, gap_s, handed)

    def _handed(self, framer: Framer, handler: Handler, piece: Piece) -> None:
        """The watch ended: a gap or the deadline hands bytes held as an echo to ``framer``."""
        if piece is None and self._held:
            framer.feed(self.passed(b"", cut_short=True))  # an echo cut short is no echo
        handler(piece)

    def unwatch(self) -> None:
        """Stop a :meth:`watch_frame`."""
        self._inner_framing().unwatch()

    def check_open(self) -> None:
        """As the wrapped transport's."""
        self._inner_framing().check_open()

    @property
    def framing(self) -> EchoCancellingTransport | None:
        """Callback powers where the wrapped transport has them."""
        return self if self._inner.framing is not None else None

    def _inner_framing(self) -> Framing:
        framing = self._inner.framing
        if framing is None:
            raise PortError("the wrapped transport cannot frame in callbacks")
        return framing

    @property
    def received_at(self) -> float:
        """When the wrapped transport last delivered bytes."""
        return self._inner.received_at

    @property
    def adapter(self) -> Adapter | None:
        """The USB adapter behind the port, if the inner transport knows it (its latency)."""
        return self._inner.adapter

    def discard_input(self) -> bytes:
        """Drop unread input; an echo still expected is dropped with it."""
        held, self._held, self._expect = self._held, b"", b""
        return held + self._inner.discard_input()


class _EchoFilter:
    """A framer in front of the reader's: the echo is taken off what it is fed."""

    __slots__ = ("echo", "inner")

    def __init__(self, echo: EchoCancellingTransport, inner: Framer) -> None:
        self.echo = echo
        self.inner = inner

    def feed(self, data: bytes) -> None:
        passed = self.echo.passed(data)
        if passed:
            self.inner.feed(passed)

    def next_frame(self) -> Frame | Skipped | None:
        return self.inner.next_frame()

    def reset(self) -> None:
        self.inner.reset()

    @property
    def buffered(self) -> int:
        return self.inner.buffered + self.echo.held
