"""A reply a USB adapter splits at its latency tick is still one reply to the master."""

from __future__ import annotations

import asyncio
import random

from fcmaster.bus.link import Link
from fcmaster.bus.plan import LinePlan
from fcmaster.clock import MonotonicClock
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.sim import DriveSettings, LineSettings, PtyServer, build_line
from fcmaster.transport.serial import SerialTransport
from fcmaster.transport.usb import Adapter

LATENCY_MS = 16
POLLS = 24
# At 19200 baud a 16-byte reply lasts 9.2 ms: about half of the replies span one of the
# adapter's 16 ms ticks and reach the master in two chunks.
LINE = LineSettings(protocol="danfoss-fc", baudrate=19200, adapter_latency_ms=LATENCY_MS)
FTDI = Adapter(
    device="/dev/ttyUSB0", driver="ftdi_sio", by_id=None, by_path=None, latency_ms=LATENCY_MS
)


async def _poll(*, adapter_known: bool) -> tuple[Link, int]:
    """POLLS polls of drive 3 through the simulated adapter: the Link and the chunks sent."""
    clock = MonotonicClock()
    built = build_line(LINE, [(3, DriveSettings())], clock=clock)
    async with asyncio.timeout(30), PtyServer(built, clock=clock) as server:
        transport = SerialTransport(server.device, baudrate=19200, parity="E")
        await transport.open()
        try:
            # What tune() reads from sysfs for an FTDI adapter whose timer stays at 16 ms.
            transport.adapter = FTDI if adapter_known else None
            plan = LinePlan(name="line", port=server.device, baudrate=19200)
            codec = FcCodec()
            link = Link(plan, codec=codec, transport=transport, clock=clock)
            exchange = codec.poll(3, None, codec.parameter("16-13"))
            rng = random.Random(7)
            for _ in range(POLLS):
                # At a random phase of the adapter's timer: a master answered right after
                # a tick would otherwise lock onto it and always see the same split.
                await asyncio.sleep(rng.uniform(0.0, LATENCY_MS / 1000))
                await link.transact(exchange)
        finally:
            await transport.close()
        assert server.line.adapter is not None
        return link, server.line.adapter.chunks


async def test_a_reply_split_at_the_adapters_tick_is_taken_whole_when_its_latency_is_known() -> (
    None
):
    link, chunks = await _poll(adapter_known=True)
    stats = link.stats
    assert chunks > stats.requests  # some replies did come in two chunks
    assert stats.noise_bytes == 0  # and none was cut at the tick into pieces
    assert stats.replies + stats.timeouts == POLLS
    # The simulator shares this process's event loop: a stall of it (a full garbage
    # collection late in a long test session) can make a reply late. Such a reply is
    # whole, discarded before the next request; one cut in two would be noise above.
    assert stats.timeouts * 16 <= stats.late_bytes, stats
    assert stats.timeouts <= 2, stats
    assert link.gap_s > LATENCY_MS / 1000


async def test_without_the_latency_the_plans_gap_cuts_split_replies_in_two() -> None:
    # The same line with the adapter unknown (a pty, an adapter without a latency timer):
    # what the wider gap prevents.
    link, chunks = await _poll(adapter_known=False)
    assert chunks > link.stats.requests
    assert link.stats.noise_bytes > 0
    assert link.stats.timeouts > 0
    assert link.gap_s == LinePlan(name="line", port="x", baudrate=19200).gap_s
