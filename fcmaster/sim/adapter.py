"""A simulated USB serial adapter between the line and the master: the latency timer.

An FTDI chip does not pass each received byte to the host: it collects them and sends a
USB packet when its latency timer ticks (every ``latency_s``, 16 ms by default on Linux)
or when a packet's worth (62 bytes) is waiting. A short reply therefore reaches the master
at the first tick after it arrived, and a reply that spans a tick arrives in two chunks.
The timer runs freely from the line's start.

The line hands a burst over when its last character has arrived; each byte's arrival is
worked back from that at the line's character time. Bytes that arrived before a tick the
line had already passed go out at once, so the first chunk of a reply that spans a tick
comes when the reply ends instead of at the tick: it is incomplete either way, and the
master can do nothing with it earlier.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Final

from fcmaster.errors import UsageError

FTDI_PACKET: Final = 62  # payload bytes of a full-speed FTDI packet (64 less 2 status bytes)


class LatencyAdapter:
    """Holds the bytes for the master until its latency timer ticks or a packet is full."""

    def __init__(self, latency_s: float, *, epoch: float, packet: int = FTDI_PACKET) -> None:
        if not (latency_s > 0 and math.isfinite(latency_s)) or packet < 1:
            raise UsageError("an adapter's latency must be above 0 s and its packet ≥ 1 byte")
        self.latency_s = latency_s
        self.packet = packet
        self._epoch = epoch
        self._held: deque[tuple[float, int]] = deque()  # (arrival, byte)
        self.chunks = 0  # packets released, for tests and benchmarks

    def hold(self, data: bytes | bytearray, end: float, char_s: float) -> None:
        """``data`` arrived at the adapter, its last character ending at ``end``."""
        last = len(data) - 1
        self._held.extend((end - (last - i) * char_s, byte) for i, byte in enumerate(data))

    def next_release(self) -> float | None:
        """When the adapter next sends bytes to the master, or None if it holds none."""
        held = self._held
        if not held:
            return None
        tick = self._tick_at_or_after(held[0][0])
        if len(held) >= self.packet:
            return min(tick, held[self.packet - 1][0])  # a full packet goes at once
        return tick

    def release(self, now: float) -> bytes:
        """The bytes sent to the master by ``now``, in order."""
        out = bytearray()
        while (due := self.next_release()) is not None and due <= now:
            taken = 0
            while self._held and taken < self.packet and self._held[0][0] <= due:
                out.append(self._held.popleft()[1])
                taken += 1
            self.chunks += 1
        return bytes(out)

    def _tick_at_or_after(self, t: float) -> float:
        ticks = math.ceil((t - self._epoch) / self.latency_s - 1e-9)
        return self._epoch + max(ticks, 0) * self.latency_s
