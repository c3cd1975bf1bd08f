"""Local-echo suppression for two-wire adapters that hear their own transmission."""

from __future__ import annotations

import asyncio
from typing import Any

from fcmaster.errors import ReplyTimeout
from fcmaster.transport.pipe import Transport


class EchoCancellingTransport:
    """Wraps a transport and removes the echo of each request from what is read back.

    The echo comes first and byte for byte. Bytes that match it so far are held back until
    the whole echo is in, and only then dropped; as soon as a byte differs (a collision, or
    an adapter that did not echo after all) the held bytes and the rest are passed on
    untouched, so a reply that merely starts like the request (FC: STX, LGE, ADR) is never
    eaten.
    """

    __slots__ = ("_expect", "_held", "_inner")

    def __init__(self, inner: Transport) -> None:
        self._inner = inner
        self._expect = b""  # the echo still awaited, whole
        self._held = b""  # bytes read that match the start of ``_expect``

    async def open(self) -> None:
        """Open the wrapped transport."""
        await self._inner.open()

    async def close(self) -> None:
        """Close the wrapped transport."""
        await self._inner.close()

    async def appeared(self) -> None:
        """As the wrapped transport's (a device node that reappears); never if it has none."""
        appeared = getattr(self._inner, "appeared", None)
        if appeared is None:
            await asyncio.Event().wait()
        else:
            await appeared()

    async def write(self, data: bytes) -> None:
        """Write, and expect ``data`` back first."""
        self._expect = data
        await self._inner.write(data)

    async def read(self, deadline: float) -> bytes:
        """Read past the echo."""
        while True:
            cut_short = False
            try:
                data = await self._inner.read(deadline)
            except ReplyTimeout:
                if not self._held:
                    raise
                data, cut_short = b"", True  # an echo cut short is no echo
            if not self._expect:
                return data
            data, self._held = self._held + data, b""
            expect = self._expect
            if data[: len(expect)] == expect:  # the whole echo: drop it
                self._expect, data = b"", data[len(expect) :]
            elif expect.startswith(data) and not cut_short:  # an echo so far: wait for the rest
                self._held = data
                continue
            else:  # diverged, or cut short: no echo, hand everything back
                self._expect = b""
            if data:
                return data

    @property
    def received_at(self) -> float:
        """When the wrapped transport last delivered bytes."""
        return self._inner.received_at

    @property
    def adapter(self) -> Any:
        """The USB adapter behind the port, if the inner transport knows it (its latency)."""
        return getattr(self._inner, "adapter", None)

    def discard_input(self) -> bytes:
        """Drop unread input; an echo still expected is dropped with it."""
        held, self._held, self._expect = self._held, b"", b""
        return held + self._inner.discard_input()
