"""Local-echo suppression for two-wire adapters that hear their own transmission."""

from __future__ import annotations

from fcmaster.bus.transport import Transport


class EchoCancellingTransport:
    """Wraps a transport and removes the echo of each request from what is read back.

    The echo comes first and byte for byte; as soon as a byte differs (a collision, or an
    adapter that did not echo after all) the rest is passed on untouched, so a real reply
    is never eaten.
    """

    __slots__ = ("_expect", "_inner")

    def __init__(self, inner: Transport) -> None:
        self._inner = inner
        self._expect = b""

    async def open(self) -> None:
        """Open the wrapped transport."""
        await self._inner.open()

    async def close(self) -> None:
        """Close the wrapped transport."""
        await self._inner.close()

    async def write(self, data: bytes) -> None:
        """Write, and expect ``data`` back first."""
        self._expect = data
        await self._inner.write(data)

    async def read(self, deadline: float) -> bytes:
        """Read past the echo."""
        while True:
            data = await self._inner.read(deadline)
            if not self._expect:
                return data
            matched = 0
            limit = min(len(data), len(self._expect))
            while matched < limit and data[matched] == self._expect[matched]:
                matched += 1
            if matched < limit:  # diverged: no (more) echo
                self._expect = b""
            else:
                self._expect = self._expect[matched:]
            if matched < len(data):
                return data[matched:]

    def discard_input(self) -> bytes:
        """Drop unread input; an echo still expected is dropped with it."""
        self._expect = b""
        return self._inner.discard_input()
