"""Simulated drives on a real pseudo-terminal, talked to with plain pyserial.

The server runs on the test's event loop; each client runs in a worker thread with its own
blocking pyserial port, as another program would. Timing is only checked from below (a
reply never comes sooner than the wire allows); how close it comes is a benchmark figure
(benchmarks/sim_timing.py). Every test is bounded by a timeout.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import TypeVar

import pytest
import serial

from fcmaster.clock import MonotonicClock
from fcmaster.protocol.danfoss_fc import (
    FcFramer,
    Telegram,
    decode_reference,
    decode_telegram,
    encode_telegram,
    make_pke,
)
from fcmaster.protocol.framing import Frame
from fcmaster.sim import DriveSettings, FaultPlan, LineSettings, PtyServer, build_line

T = TypeVar("T")
LIMIT_S = 30.0
START = 0x047C
REF_50 = 0x2000


def frames_in(data: bytes) -> list[bytes]:
    framer = FcFramer()
    framer.feed(data)
    found = []
    while (piece := framer.next_frame()) is not None:
        if isinstance(piece, Frame):
            found.append(piece.data)
    return found


def poll(address: int, pnu: int = 1613) -> bytes:
    return encode_telegram(
        Telegram(address=address, pcd1=START, pcd2=REF_50, pke=make_pke(0x1, pnu))
    )


def pause(seconds: float) -> None:
    threading.Event().wait(seconds)  # a client thread's pause; the server loop keeps running


@contextlib.asynccontextmanager
async def served(
    *,
    baudrate: int = 19200,
    parity: str = "E",
    faults: FaultPlan | None = None,
    delay_s: float | None = None,
    link: str | None = None,
) -> AsyncIterator[PtyServer]:
    clock = MonotonicClock()
    line = build_line(
        LineSettings(baudrate=baudrate, parity=parity, faults=faults or FaultPlan()),
        [(a, DriveSettings(response_delay_s=delay_s)) for a in (1, 2, 3)],
        clock=clock,
    )
    async with asyncio.timeout(LIMIT_S), PtyServer(line, clock=clock, link=link) as server:
        yield server


async def in_client(work: Callable[[], T]) -> T:
    return await asyncio.to_thread(work)


def read_reply(port: serial.Serial, length: int, wait_s: float) -> tuple[bytes, float]:
    """Bytes until a whole frame came (or ``wait_s``), and when the last of them arrived.

    The port must have a short timeout already. Setting ``port.timeout`` here instead would
    re-apply the termios on every read, and a pty refuses a second parity setting made
    before the server has put its baseline back (see fcmaster.sim.pty).
    """
    data = b""
    end = time.monotonic() + wait_s
    arrived = time.monotonic()
    while time.monotonic() < end and not (len(data) >= length and frames_in(data)):
        chunk = port.read(max(port.in_waiting, 1))
        if chunk:
            data += chunk
            arrived = time.monotonic()
        elif len(data) >= length:
            break  # a whole reply's worth came and then a pause: a broken reply
    return data, arrived


async def test_requests_get_correct_replies() -> None:
    async with served() as server:

        def client() -> list[Telegram]:
            with serial.Serial(server.path, 19200, parity="E", timeout=0.2) as port:
                replies = []
                for address in (1, 2, 3):
                    port.write(poll(address))
                    replies.append(decode_telegram(port.read(16), from_drive=True))
                port.write(poll(9))  # nobody at 9
                assert port.read(16) == b""
                return replies

        replies = await in_client(client)
    assert [r.address for r in replies] == [1, 2, 3]
    assert all(r.pnu == 1613 and r.pcd1 & 0x0800 for r in replies)  # running since this poll


@pytest.mark.parametrize("baudrate", [9600, 19200, 115200])
async def test_replies_never_arrive_sooner_than_the_wire_allows(baudrate: int) -> None:
    async with served(baudrate=baudrate) as server:
        wire_s = (16 + 16) * 11 / baudrate + 0.010

        def client() -> list[float]:
            took = []
            with serial.Serial(server.path, baudrate, parity="E", timeout=1.0) as port:
                for _ in range(10):
                    written = time.monotonic()
                    port.write(poll(2))
                    reply = port.read(16)
                    took.append(time.monotonic() - written)
                    assert frames_in(reply) == [reply]
            return took

        took = await in_client(client)
    assert min(took) >= wire_s


async def test_a_request_during_a_reply_collides_and_garbles_both() -> None:
    # At 2400 baud a 16-byte telegram lasts 73 ms. With a 100 ms response delay drive 1's
    # reply is on the wire from 173 ms to 246 ms after the first request arrived, so a
    # second request written at 170 ms overlaps it even if it is 70 ms early or late.
    async with served(baudrate=2400, delay_s=0.100) as server:

        def client() -> bytes:
            with serial.Serial(server.path, 2400, parity="E", timeout=0.002) as port:
                port.write(poll(1))
                pause(0.170)
                port.write(poll(2))
                data, _ = read_reply(port, 32, 0.6)
                return data

        data = await in_client(client)
        assert server.line.counters.collisions >= 1
        assert server.line.counters.requests == 1  # drive 2 never heard a valid request
    assert frames_in(data) == []


async def test_every_fault_kind_happens_at_its_rate_and_looks_right_to_the_client() -> None:
    rate, late_s, n = 0.15, 0.020, 200
    faults = FaultPlan(drop=rate, corrupt=rate, noise=rate, late=rate, late_s=late_s, seed=11)
    async with served(baudrate=115200, faults=faults, delay_s=0.005) as server:
        wire_s = 32 * 11 / 115200 + 0.005

        def client() -> list[tuple[bytes, float]]:
            seen = []
            with serial.Serial(server.path, 115200, parity="E", timeout=0.002) as port:
                for _ in range(n):
                    port.reset_input_buffer()
                    written = time.monotonic()
                    port.write(poll(1))
                    # generous: a loaded machine may serve the pty late (never early)
                    data, arrived = read_reply(port, 16, 0.250)
                    seen.append((data, arrived - written))
            return seen

        seen = await in_client(client)
        records = list(server.line.transactions)
    assert len(records) == n
    for (data, took), record in zip(seen, records, strict=True):
        frames = frames_in(data)
        if "drop" in record.faults:
            assert not frames
        elif "corrupt" in record.faults:
            assert not frames
            assert len(data) >= 16
        else:
            assert frames, record
            minimum = wire_s + (late_s if "late" in record.faults else 0.0)
            assert took >= minimum
    for kind in ("drop", "corrupt", "late"):
        count = sum(kind in record.faults for record in records)
        assert count / n == pytest.approx(rate, abs=0.08), kind
    assert server.line.counters.noise_bursts / n == pytest.approx(rate, abs=0.08)
    noisy = sum(len(data) > 16 for data, _ in seen)
    assert noisy >= server.line.counters.noise_bursts // 2  # bursts reach the client


async def test_local_echo_returns_the_master_bytes_first() -> None:
    async with served(faults=FaultPlan(echo=True)) as server:

        def client() -> bytes:
            with serial.Serial(server.path, 19200, parity="E", timeout=1.0) as port:
                port.write(poll(1))
                return bytes(port.read(32))

        data = await in_client(client)
    assert data[:16] == poll(1)
    assert frames_in(data[16:])[0][2] == 0x81


async def test_clients_can_reopen_the_pty_with_parity(tmp_path: Path) -> None:
    # Linux strips PARENB from a pty; glibc then refuses a second identical open (EINVAL)
    # unless the server has put its baseline termios back in between (fcmaster.sim.pty).
    async with served(parity="E", link=str(tmp_path / "ttyFC")) as server:

        def client() -> list[float]:
            values = []
            for _ in range(3):
                with serial.Serial(server.device, 19200, parity="E", timeout=1.0) as port:
                    port.write(poll(3))
                    reply = decode_telegram(port.read(16), from_drive=True)
                    values.append(decode_reference(reply.pcd2))
                pause(0.050)  # a client coming back, not one racing the server
            return values

        values = await in_client(client)
    assert len(values) == 3
    assert not (tmp_path / "ttyFC").exists()  # the link goes with the server


def test_cli_serves_a_line_until_sigterm_and_removes_its_link(tmp_path: Path) -> None:
    link = tmp_path / "ttyFC"
    command = [sys.executable, "-m", "fcmaster", "sim", "--addresses", "1-4",
               "--baudrate", "38400", "--parity", "O", "--link", str(link),
               "--name", "busA", "--faults", "seed=3"]  # fmt: skip
    with subprocess.Popen(command, stdout=subprocess.PIPE, text=True, env=os.environ) as process:
        try:
            assert process.stdout is not None
            assert process.stdout.readline().split() == ["busA", str(link)]
            with serial.Serial(str(link), 38400, parity="O", timeout=2.0) as port:
                port.write(poll(4))
                assert decode_telegram(port.read(16), from_drive=True).address == 4
            process.send_signal(signal.SIGTERM)
            assert process.wait(timeout=10) == 0
            assert not link.exists()
        finally:
            if process.poll() is None:
                process.kill()
