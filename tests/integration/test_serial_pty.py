"""SerialTransport through a real pseudo-terminal: the same termios path as a UART."""

import asyncio
import contextlib
import os
import tty
from collections.abc import AsyncIterator, Iterator
from typing import Any

import pytest

from fcmaster.clock import MonotonicClock
from fcmaster.errors import PortError, ReplyTimeout
from fcmaster.protocol.danfoss_fc.framer import FcFramer
from fcmaster.protocol.framing import Frame, Framer, Skipped, SkipReason
from fcmaster.transport.receiver import Piece
from fcmaster.transport.serial import SerialTransport, is_pty
from tests.integration.waiting import wait_for


@pytest.fixture
def pty_pair() -> Iterator[tuple[int, str]]:
    """The controlling side's fd (our stand-in for the line) and the device path."""
    controller, device = os.openpty()
    tty.setraw(device)
    path = os.ttyname(device)
    try:
        yield controller, path
    finally:
        os.close(controller)
        os.close(device)


@contextlib.asynccontextmanager
async def opened(port: str, **settings: Any) -> AsyncIterator[SerialTransport]:
    """A SerialTransport on ``port``, open for the block and closed after it."""
    transport = SerialTransport(port, **settings)
    await transport.open()
    try:
        yield transport
    finally:
        await transport.close()


async def test_bytes_go_out_in_one_write_and_replies_come_back(
    pty_pair: tuple[int, str],
) -> None:
    controller, path = pty_pair
    clock = MonotonicClock()
    async with opened(path, baudrate=19200, parity="E") as transport:
        await transport.write(b"\x02\x06\x81\x04\x7c\x20\x00\xdd")
        await asyncio.sleep(0.01)
        assert os.read(controller, 64) == b"\x02\x06\x81\x04\x7c\x20\x00\xdd"
        os.write(controller, b"\x02\x06\x81\x0f\x07\x20\x00\x2f")
        async with asyncio.timeout(2):
            got = b""
            while len(got) < 8:
                got += await transport.read(clock.now() + 1.0)
        assert got == b"\x02\x06\x81\x0f\x07\x20\x00\x2f"


async def test_bytes_are_stamped_when_they_arrive_not_when_they_are_read(
    pty_pair: tuple[int, str],
) -> None:
    # The pause after a reply counts from its arrival: a reader that gets to the bytes late
    # (another callback ran first) must still learn when they came.
    controller, path = pty_pair
    clock = MonotonicClock()
    async with opened(path, baudrate=19200) as transport:
        sent_at = clock.now()
        os.write(controller, b"\x02\x06\x81")
        # The loop takes the bytes in; nobody reads them yet.
        await wait_for(lambda: transport.received_at > 0.0, timeout_s=5.0)
        await asyncio.sleep(0.01)
        read_at = clock.now()
        assert await transport.read(read_at + 1.0) == b"\x02\x06\x81"
        assert sent_at <= transport.received_at < read_at


# A process-data reply from drive 1 (status 0x0F07, main actual value 0x2000), BCC 0xAD.
FC_REPLY = b"\x02\x06\x81\x0f\x07\x20\x00\xad"


async def read_frame(
    transport: SerialTransport, framer: Framer, deadline: float, gap_s: float
) -> Piece:
    """The next piece through ``watch_frame``, awaited as the Link awaits a reply."""
    waiter: asyncio.Future[Piece] = asyncio.get_running_loop().create_future()
    piece = transport.watch_frame(framer, deadline, gap_s, waiter.set_result)
    if piece is None:
        try:
            piece = await waiter
        finally:
            transport.unwatch()
    if piece is None:
        transport.check_open()
    return piece


async def test_a_frame_read_is_fed_in_the_callback_and_wakes_once_when_whole(
    pty_pair: tuple[int, str],
) -> None:
    # A reply split in chunks (a UART's FIFO, a USB adapter's batches) is fed to the
    # framer as it arrives; the reader resumes once, with the whole frame, stamped with the
    # arrival of the chunk that completed it.
    controller, path = pty_pair
    clock = MonotonicClock()
    framer = FcFramer()
    async with opened(path, baudrate=19200) as transport:
        reader = asyncio.create_task(read_frame(transport, framer, clock.now() + 5.0, 1.0))
        await asyncio.sleep(0.01)
        os.write(controller, FC_REPLY[:3])
        await wait_for(lambda: framer.buffered == 3, timeout_s=5.0)
        os.write(controller, FC_REPLY[3:5])
        await wait_for(lambda: framer.buffered == 5, timeout_s=5.0)
        assert not reader.done()  # fed, not woken
        last_sent_at = clock.now()
        os.write(controller, FC_REPLY[5:])
        async with asyncio.timeout(5):
            piece = await reader
        assert piece == Frame(FC_REPLY)
        assert transport.received_at >= last_sent_at
        assert framer.buffered == 0


async def test_a_frame_read_ends_at_a_gap_after_an_unfinished_frame(
    pty_pair: tuple[int, str],
) -> None:
    controller, path = pty_pair
    clock = MonotonicClock()
    framer = FcFramer()
    async with opened(path, baudrate=19200) as transport:
        deadline = clock.now() + 5.0
        os.write(controller, FC_REPLY[:4])
        async with asyncio.timeout(5):
            piece = await read_frame(transport, framer, deadline, 0.05)
        # Not the deadline: the gap after the half frame ended the read.
        assert piece is None
        assert clock.now() < deadline
        assert clock.now() >= transport.received_at + 0.05
        framer.reset()
        assert framer.next_frame() == Skipped(FC_REPLY[:1], SkipReason.GAP)


async def test_a_frame_begun_in_an_earlier_read_is_cut_one_gap_after_its_last_chunk(
    pty_pair: tuple[int, str],
) -> None:
    # A read that starts with part of a frame in hand (the Link reads on after a piece
    # that was not the reply) gives the frame a gap after its latest chunk, not after
    # the chunks it had when the read began: a frame in three chunks is taken whole.
    controller, path = pty_pair
    clock = MonotonicClock()
    framer = FcFramer()
    gap = 0.5
    async with opened(path, baudrate=19200) as transport:
        os.write(controller, FC_REPLY[:3])
        await wait_for(lambda: transport.received_at > 0.0, timeout_s=5.0)
        first_at = transport.received_at
        await asyncio.sleep(0.2)  # nobody reads yet: the chunk waits in the buffer
        reader = asyncio.create_task(read_frame(transport, framer, clock.now() + 5.0, gap))
        await asyncio.sleep(0.1)
        os.write(controller, FC_REPLY[3:5])
        await wait_for(lambda: framer.buffered == 5, timeout_s=5.0)
        middle_at = transport.received_at
        # Past a gap after the first chunk, well inside one after the second.
        await asyncio.sleep(max(0.0, first_at + gap + 0.1 - clock.now()))
        assert clock.now() < middle_at + gap - 0.05
        os.write(controller, FC_REPLY[5:])
        async with asyncio.timeout(5):
            piece = await reader
        assert piece == Frame(FC_REPLY)
        assert transport.received_at - middle_at < gap


async def test_a_read_with_nothing_arriving_times_out_at_its_deadline(
    pty_pair: tuple[int, str],
) -> None:
    _, path = pty_pair
    clock = MonotonicClock()
    async with opened(path, baudrate=19200) as transport:
        deadline = clock.now() + 0.05
        with pytest.raises(ReplyTimeout):
            await transport.read(deadline)
        assert clock.now() >= deadline


class _ShiftedClock(MonotonicClock):
    """A real clock whose timebase is not the event loop's (an hour ahead)."""

    SHIFT_S = 3600.0

    def now(self) -> float:
        return super().now() + self.SHIFT_S


async def test_arrivals_and_deadlines_are_on_the_transports_clock_not_the_loops(
    pty_pair: tuple[int, str],
) -> None:
    controller, path = pty_pair
    clock = _ShiftedClock()
    framer = FcFramer()
    async with opened(path, baudrate=19200, clock=clock) as transport:
        # On the loop's timebase this deadline would be an hour away; on the clock's it is
        # 50 ms, and the read ends then.
        deadline = clock.now() + 0.05
        async with asyncio.timeout(5):
            assert await read_frame(transport, framer, deadline, 0.01) is None
            with pytest.raises(ReplyTimeout):
                await transport.read(clock.now() + 0.05)
        assert clock.now() >= deadline
        before = clock.now()
        os.write(controller, FC_REPLY)
        async with asyncio.timeout(5):
            piece = await read_frame(transport, framer, clock.now() + 5.0, 1.0)
        assert piece == Frame(FC_REPLY)
        assert before <= transport.received_at <= clock.now()  # stamped on the clock


async def test_stale_input_is_discarded_and_returned(pty_pair: tuple[int, str]) -> None:
    controller, path = pty_pair
    async with opened(path, baudrate=19200) as transport:
        os.write(controller, b"late reply")
        await asyncio.sleep(0.05)
        assert transport.discard_input() == b"late reply"
        assert transport.discard_input() == b""


async def test_reopening_a_pty_with_parity_works_although_the_kernel_refuses_it(
    pty_pair: tuple[int, str],
) -> None:
    _, path = pty_pair
    assert is_pty(path)
    for _ in range(3):  # the second open of a pty with parity E fails with EINVAL in termios
        transport = SerialTransport(path, baudrate=19200, parity="E")
        await transport.open()
        await transport.close()


async def test_a_missing_port_is_a_port_error_that_says_what_to_check() -> None:
    transport = SerialTransport("/dev/fcmaster-no-such-port", baudrate=9600)
    with pytest.raises(PortError, match="check the device path"):
        await transport.open()


async def test_a_port_that_disappears_raises_port_error_on_read() -> None:
    controller, device = os.openpty()
    tty.setraw(device)
    transport = SerialTransport(os.ttyname(device), baudrate=19200)
    await transport.open()
    os.close(device)
    os.close(controller)  # the line goes away under the open transport (adapter unplugged)
    clock = MonotonicClock()

    async def read_until_lost() -> None:
        async with asyncio.timeout(2):  # a port that never reports the loss fails the test
            while True:
                with contextlib.suppress(ReplyTimeout):
                    await transport.read(clock.now() + 0.2)

    try:
        with pytest.raises(PortError):
            await read_until_lost()
    finally:
        await transport.close()


async def test_a_write_larger_than_the_kernel_takes_at_once_arrives_whole_and_in_order(
    pty_pair: tuple[int, str],
) -> None:
    controller, path = pty_pair
    data = bytes(range(256)) * 1024  # far more than a pty buffers
    os.set_blocking(controller, False)
    async with opened(path, baudrate=115200, parity="N") as transport:
        await transport.write(data[: len(data) // 2])
        await transport.write(data[len(data) // 2 :])  # queued behind the unsent rest
        received = bytearray()
        async with asyncio.timeout(5):
            while len(received) < len(data):
                try:
                    received += os.read(controller, 65536)
                except BlockingIOError:
                    await asyncio.sleep(0.001)
        assert received == data


async def test_a_socket_url_goes_through_the_same_transport() -> None:
    """Serial device servers (``socket://``) have no serial descriptor of their own."""
    heard: asyncio.Queue[bytes] = asyncio.Queue()
    served = asyncio.Event()

    async def device_server(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            heard.put_nowait(await reader.readexactly(4))
            writer.write(b"pong")
            await writer.drain()
            await reader.read()  # until the transport closes
        finally:
            writer.close()
            with contextlib.suppress(ConnectionError):
                await writer.wait_closed()
            served.set()

    server = await asyncio.start_server(device_server, "127.0.0.1", 0)
    host, port = server.sockets[0].getsockname()[:2]
    transport = SerialTransport(f"socket://{host}:{port}", baudrate=19200)
    clock = MonotonicClock()
    try:
        async with asyncio.timeout(5):
            await transport.open()
            await transport.write(b"ping")
            assert await heard.get() == b"ping"
            got = b""
            while len(got) < 4:
                got += await transport.read(clock.now() + 1.0)
        assert got == b"pong"
    finally:
        await transport.close()
        async with asyncio.timeout(5):
            await served.wait()  # the server's side is closed before the loop is
        server.close()
        await server.wait_closed()
