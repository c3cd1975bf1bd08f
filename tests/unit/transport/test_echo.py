"""Local-echo suppression: an exact echo of the request is stripped, and nothing else."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field

import pytest

from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.errors import ReplyTimeout
from fcmaster.protocol.danfoss_fc import Telegram, encode_telegram
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.danfoss_fc.framer import FcFramer
from fcmaster.protocol.framing import Frame, Skipped, SkipReason
from fcmaster.transport.echo import EchoCancellingTransport
from tests.fakes import ScriptedTransport, Timed, VirtualClock
from tests.unit.bus.fcdrive import FcDrive, FcLine

REQUEST = encode_telegram(Telegram(address=1, pcd1=0x047C, pcd2=0x2000))
# A drive's reply starts like the request: STX, LGE, ADR.
REPLY = encode_telegram(Telegram(address=1, pcd1=0x0B07, pcd2=0x2000))


@dataclass
class Chunks:
    """A transport whose reads return ``chunks`` one by one, then time out."""

    chunks: list[bytes]
    written: list[bytes] = field(default_factory=list)
    stale: bytes = b""
    received_at: float = 0.0

    async def open(self) -> None:
        pass

    async def close(self) -> None:
        pass

    async def write(self, data: bytes) -> None:
        self.written.append(data)

    async def read(self, deadline: float) -> bytes:
        if not self.chunks:
            raise ReplyTimeout("nothing more")
        return self.chunks.pop(0)

    def discard_input(self) -> bytes:
        stale, self.stale = self.stale, b""
        return stale

    framing = None  # replies are awaited, as on the inner line
    adapter = None

    async def appeared(self) -> None:
        await asyncio.Event().wait()  # no device node


async def read_all(transport: EchoCancellingTransport) -> bytes:
    data = b""
    while True:
        try:
            data += await transport.read(0.0)
        except ReplyTimeout:
            return data


async def exchange(*chunks: bytes) -> bytes:
    echo = EchoCancellingTransport(Chunks(list(chunks)))
    await echo.write(REQUEST)
    return await read_all(echo)


@pytest.mark.parametrize(
    "chunks",
    [
        pytest.param((REQUEST, REPLY), id="echo-then-reply"),
        pytest.param((REQUEST + REPLY,), id="one-chunk"),
        pytest.param((REQUEST[:3], REQUEST[3:5], REQUEST[5:] + REPLY[:2], REPLY[2:]), id="split"),
        pytest.param(tuple(bytes((b,)) for b in REQUEST + REPLY), id="byte-by-byte"),
    ],
)
async def test_exact_echo_is_stripped_however_it_is_cut(chunks: tuple[bytes, ...]) -> None:
    assert await exchange(*chunks) == REPLY


async def test_read_returns_the_reply_not_an_empty_chunk_after_the_echo() -> None:
    echo = EchoCancellingTransport(Chunks([REQUEST, REPLY]))
    await echo.write(REQUEST)
    assert await echo.read(0.0) == REPLY


async def test_reply_without_an_echo_passes_whole_though_it_starts_like_the_request() -> None:
    assert REPLY[:3] == REQUEST[:3]
    assert await exchange(REPLY) == REPLY


async def test_reply_without_an_echo_passes_whole_when_read_byte_by_byte() -> None:
    assert await exchange(*(bytes((b,)) for b in REPLY)) == REPLY


async def test_echo_that_diverges_is_not_an_echo_and_all_of_it_passes() -> None:
    garbled = REQUEST[:5] + b"\xff" + REQUEST[6:]
    assert await exchange(garbled[:4], garbled[4:], REPLY) == garbled + REPLY


async def test_truncated_echo_is_handed_back_at_the_deadline() -> None:
    assert await exchange(REQUEST[:4]) == REQUEST[:4]


async def test_bytes_after_the_echo_are_never_stripped_even_if_they_repeat_it() -> None:
    assert await exchange(REQUEST, REQUEST) == REQUEST


async def test_discard_input_ends_the_wait_for_an_echo() -> None:
    inner = Chunks([REQUEST], stale=b"\x01\x02")
    echo = EchoCancellingTransport(inner)
    await echo.write(REQUEST)
    assert echo.discard_input() == b"\x01\x02"
    assert await read_all(echo) == REQUEST
    assert inner.written == [REQUEST]


async def test_master_on_an_echoing_adapter_sees_only_the_replies() -> None:
    clock = VirtualClock()
    line = FcLine(FcDrive(1))

    def echoing(request: bytes) -> Timed | None:
        reply = line(request)
        wire_s = len(request) * 11 / 19200
        pieces: list[tuple[float, bytes]] = [(wire_s, request)]
        if reply is not None:
            pieces.append((wire_s + 0.010 + len(reply) * 11 / 19200, reply))
        return Timed(tuple(pieces))

    plan = LinePlan(
        name="line1", port="scripted", echo=True, drives=(DrivePlan(name="a", address=1),)
    )
    inner = ScriptedTransport(clock, echoing)
    master = BusMaster(plan, codec=FcCodec(), transport=EchoCancellingTransport(inner), clock=clock)
    async with master:
        await clock.run_for(0.5)
    stats = master.stats
    assert stats.requests > 10
    assert stats.timeouts == 0
    assert stats.replies >= stats.requests - 1  # one may be in flight
    assert (stats.noise_bytes, stats.late_bytes, stats.unexpected) == (0, 0, 0)


async def watched(*chunks: bytes, gap_s: float = 0.005) -> list[Frame | Skipped | None]:
    """What a reader framing in callbacks gets after REQUEST, the line bringing ``chunks``.

    The chunks arrive 1 ms apart; pieces are taken until the framer has none left and a gap
    has passed (None).
    """
    clock = VirtualClock()
    inner = ScriptedTransport(
        clock, lambda _: Timed(tuple((0.001 * (i + 1), c) for i, c in enumerate(chunks)))
    )
    echo = EchoCancellingTransport(inner)
    framing = echo.framing
    assert framing is not None
    await echo.open()
    framing.write_now(REQUEST)
    framer = FcFramer()
    pieces: list[Frame | Skipped | None] = []
    while True:
        waiter: asyncio.Future[Frame | Skipped | None] = asyncio.get_running_loop().create_future()
        piece = framing.watch_frame(framer, clock.now() + 1.0, gap_s, waiter.set_result)
        if piece is None:
            piece = await clock.complete(waiter)
        if piece is None:
            framer.reset()
            rest = []
            while (left := framer.next_frame()) is not None:
                rest.append(left)
            pieces.extend(rest)
            return pieces
        pieces.append(piece)


@pytest.mark.parametrize(
    "chunks",
    [
        pytest.param((REQUEST, REPLY), id="echo-then-reply"),
        pytest.param((REQUEST + REPLY,), id="one-chunk"),
        pytest.param((REQUEST[:3], REQUEST[3:5], REQUEST[5:] + REPLY[:2], REPLY[2:]), id="split"),
        pytest.param(tuple(bytes((b,)) for b in REQUEST + REPLY), id="byte-by-byte"),
    ],
)
async def test_in_the_reader_callback_the_echo_is_stripped_however_it_is_cut(
    chunks: tuple[bytes, ...],
) -> None:
    assert await watched(*chunks) == [Frame(REPLY)]


async def test_in_the_reader_callback_a_reply_like_the_request_is_not_eaten() -> None:
    assert await watched(*(bytes((b,)) for b in REPLY)) == [Frame(REPLY)]


async def test_in_the_reader_callback_a_truncated_echo_is_handed_on_at_the_gap() -> None:
    # Held as the start of an echo until the gap; then it is no echo, and the framer gets it
    # (an unfinished frame, skipped for the gap: counted, never lost in the filter).
    pieces = await watched(REQUEST[:4])
    assert pieces == [Skipped(REQUEST[:1], SkipReason.GAP), *pieces[1:]]
    assert b"".join(p.data for p in pieces if p is not None) == REQUEST[:4]
