"""`fcmaster capture` following a daemon's frame log over a real socket (a fake daemon).

The frames are put into the log by the test while the capture runs, so what the file must
hold is known exactly: only frames after the capture began, each once, in order, with its
direction, and a comment where the capture fell behind the ring.
"""

from __future__ import annotations

import asyncio
import io
from pathlib import Path

import pytest

from fcmaster.bus.frame_log import RX, TX, FrameLog
from fcmaster.errors import UsageError
from fcmaster.protocol import pcapng
from fcmaster.subcommands.capture import capture
from tests.integration.daemon_harness import until
from tests.integration.gateway_double import FakeGateway
from tests.integration.http_harness import VIEWER_TOKEN, serving


async def _started(output: Path) -> bool | None:
    return (
        await asyncio.to_thread(output.exists) or None
    )  # the file is written once the capture has begun


async def _packets(output: Path) -> int | None:
    return len(pcapng.decode(await asyncio.to_thread(output.read_bytes)).packets) or None


async def test_a_capture_holds_the_frames_after_its_start_in_order_and_counts_misses(
    tmp_path: Path,
) -> None:
    gateway = FakeGateway()
    log = gateway.frames["line1"] = FrameLog(gateway.clock.wall, length=8)
    log.add(TX, b"before", 1.0)  # in the ring before the capture: not part of it
    output = tmp_path / "line1.pcapng"
    said = io.StringIO()
    async with serving(gateway) as adapter:
        running = asyncio.create_task(
            capture(adapter.url, "line1", 3.0, output, VIEWER_TOKEN, out=said, poll_s=0.1)
        )
        await until(lambda: _started(output), "the capture to begin")
        log.add(TX, b"\x02\x01", 10.0)
        log.add(RX, b"\x02\x81", 10.25)
        assert await until(lambda: _packets(output), "the first frames in the file") == 2
        for n in range(20):  # more at once than the ring holds: 12 are lost
            log.add(TX, bytes([n]), 11.0 + n / 100)
        assert await asyncio.wait_for(running, 10) == 0
    file = pcapng.decode(output.read_bytes())
    (interface,) = file.interfaces
    plan = gateway.plans[0]
    assert interface.name == "line1"
    assert interface.link_type == 147
    assert interface.speed == plan.baudrate
    assert interface.description == f"danfoss-fc {plan.baudrate} 8{plan.parity}1"
    packets = file.packets
    assert [p.data for p in packets] == [b"\x02\x01", b"\x02\x81"] + [
        bytes([n]) for n in range(12, 20)
    ]
    assert [p.direction for p in packets[:3]] == [pcapng.OUTBOUND, pcapng.INBOUND, pcapng.OUTBOUND]
    # the daemon's monotonic spacing, kept to the microsecond
    assert packets[1].timestamp_us - packets[0].timestamp_us == 250_000
    assert packets[2].timestamp_us - packets[0].timestamp_us == 1_120_000
    assert packets[2].comment == "12 frames missed before this one"
    assert all(p.comment == "" for p in packets[3:])
    assert said.getvalue() == (
        f"10 frames (9 sent, 1 received) of bus line1 in {output}; 12 frames missed\n"
    )


async def test_a_capture_names_what_is_wrong_and_writes_no_file(tmp_path: Path) -> None:
    output = tmp_path / "x.pcapng"
    async with serving(FakeGateway()) as adapter:
        with pytest.raises(UsageError, match="no bus called 'south'"):
            await capture(adapter.url, "south", 1, output, VIEWER_TOKEN)
        with pytest.raises(UsageError, match="does not accept this token"):
            await capture(adapter.url, "line1", 1, output, "wrong-token-0123456789")
    with pytest.raises(UsageError, match="--seconds must be more than 0"):
        await capture("http://127.0.0.1:9", "line1", 0, output)
    with pytest.raises(UsageError, match="is not like http"):
        await capture("ftp://host", "line1", 1, output)
    assert not output.exists()
