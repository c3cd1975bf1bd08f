"""A running line captured over HTTP into pcapng, and the capture replayed on a pty.

All real: `fcmaster sim` serves the line on a pty, `fcmaster run` polls it, `fcmaster
capture` follows the daemon's frame log over a socket, and `fcmaster sim --replay` serves
the file on a new pty, where a pyserial client sends the captured requests in order and
must get the captured replies back, byte for byte.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import signal
import sys
import time
from pathlib import Path
from typing import Any

import httpx
import pytest
import serial

from fcmaster.protocol import pcapng
from fcmaster.protocol.danfoss_fc.telegram import decode_telegram
from tests.integration.daemon_harness import START_S, by_name, child, get_json, until
from tests.integration.ports import free_port

VIEWER = "viewer-token-0123456789abcdef"
SECONDS = 2.0

CONFIG = """
buses:
  - name: north
    port: {north}
    baudrate: 38400
    drives:
      - {{name: pump-1, address: 1, nominal_frequency_hz: 50, control: {control}}}
      - {{name: pump-2, address: 2, nominal_frequency_hz: 50, control: {control}}}
    simulation:
      drives:
        1: {{running_hz: 30}}
http:
  listen: 127.0.0.1:{port}
  tokens:
    - {{name: scada, role: viewer, token: {viewer}}}
"""


def exchanges(capture: pcapng.Capture) -> list[tuple[bytes, bytes]]:
    """(request, what came back before the next request) for each answered request."""
    pairs: list[tuple[bytes, bytearray]] = []
    for packet in capture.packets:
        if packet.direction == pcapng.OUTBOUND:
            pairs.append((packet.data, bytearray()))
        elif pairs:
            pairs[-1][1].extend(packet.data)
    return [(request, bytes(reply)) for request, reply in pairs if reply]


async def _capture_a_running_line(tmp_path: Path, control: str = "monitor") -> Path:
    north, port = tmp_path / "ttyNORTH", free_port()
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(north=north, port=port, viewer=VIEWER, control=control))
    output = tmp_path / "north.pcapng"
    url = f"http://127.0.0.1:{port}"
    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        assert (await sim.readline()).split()[0] == "north"
        async with (
            child("run", "--config", str(config), log=tmp_path / "run.log") as daemon,
            httpx.AsyncClient(
                base_url=url, headers={"Authorization": f"Bearer {VIEWER}"}, timeout=10
            ) as client,
        ):

            async def online() -> dict[str, Any] | None:
                drives = by_name(await get_json(client, "/api/v1/drives"))
                return drives if all(d["online"] for d in drives.values()) else None

            await until(online, "drives online", alive=daemon)
            args = ("capture", "--url", url, "--bus", "north", "--seconds", str(SECONDS))
            started = time.monotonic()
            log = tmp_path / "capture.log"
            async with child(*args, "-o", str(output), "--token", VIEWER, log=log) as cap:
                assert cap.process.stdout is not None
                said = await asyncio.wait_for(cap.process.stdout.read(), START_S)
                assert await cap.process.wait() == 0, cap.tail()
            took = time.monotonic() - started
            assert took >= SECONDS
            assert b"of bus north in" in said
            wrong = await _run_capture(url, tmp_path, "--token", "not-a-token")
            assert wrong[0] == 2
            assert "does not accept this token" in wrong[1]
            unknown = await _run_capture(url, tmp_path, "--bus", "south", "--token", VIEWER)
            assert unknown[0] == 2
            assert "no bus called 'south'" in unknown[1]
            assert (await daemon.stop(signal.SIGTERM))[0] == 0
        assert (await sim.stop())[0] == 0
    return output


async def _run_capture(url: str, tmp_path: Path, *extra: str) -> tuple[int, str]:
    log = tmp_path / "refused.log"
    log.unlink(missing_ok=True)
    args = ["capture", "--url", url, "--seconds", "1", "-o", str(tmp_path / "x.pcapng")]
    if "--bus" not in extra:
        args += ["--bus", "north"]
    async with child(*args, *extra, log=log) as cap:
        code = await asyncio.wait_for(cap.process.wait(), START_S)
    return code, log.read_text()


def _check_capture(output: Path) -> pcapng.Capture:
    capture = pcapng.decode(output.read_bytes())
    (interface,) = capture.interfaces
    assert interface.link_type == pcapng.LINK_TYPES["danfoss-fc"] == 147
    assert (interface.name, interface.description, interface.speed) == (
        "north",
        "danfoss-fc 38400 8E1",
        38400,
    )
    assert "danfoss-fc" in interface.comment
    assert "north" in interface.comment
    packets = capture.packets
    assert len(packets) > 20  # two seconds of polling at 38400 baud: dozens of exchanges
    stamps = [p.timestamp_us for p in packets]
    assert stamps == sorted(stamps)
    assert abs(stamps[0] / 1e6 - time.time()) < 120  # wall-clock time, in microseconds
    assert (stamps[-1] - stamps[0]) / 1e6 <= SECONDS + 1.0
    assert {p.direction for p in packets} == {pcapng.OUTBOUND, pcapng.INBOUND}
    pairs = exchanges(capture)
    assert len(pairs) > 10
    for request, reply in pairs:
        asked = decode_telegram(request, from_drive=False)
        answered = decode_telegram(reply, from_drive=True)
        assert asked.address == answered.address
        assert asked.address in (1, 2)
    # each reply came after its request, by at least the wire time of both frames
    for before, after in itertools.pairwise(packets):
        if before.direction == pcapng.OUTBOUND and after.direction == pcapng.INBOUND:
            wire_us = (len(before.data) + len(after.data)) * 11 / 38400 * 1e6
            assert after.timestamp_us - before.timestamp_us >= wire_us * 0.9
    return capture


def _ask(device: str, requests: list[bytes], lengths: list[int]) -> list[bytes]:
    """Send each request on ``device`` and read as many bytes as its captured reply."""
    got = []
    with serial.Serial(device, 38400, parity="E", timeout=2.0) as port:
        for request, length in zip(requests, lengths, strict=True):
            port.reset_input_buffer()
            port.write(request)
            got.append(port.read(length))
        port.write(b"\x02\x0e\x07" + b"\x00" * 12)  # never captured: no answer
        port.timeout = 0.3
        got.append(port.read(1))
        port.write(requests[0])  # after a pause: the unknown bytes were one request
        port.timeout = 2.0
        got.append(port.read(1))
    return got


async def test_a_capture_of_a_running_line_replays_the_drives_replies(tmp_path: Path) -> None:
    output = await _capture_a_running_line(tmp_path)
    capture = _check_capture(output)
    pairs = exchanges(capture)[:12]
    link = tmp_path / "ttyREPLAY"
    replay_log = tmp_path / "replay.log"
    async with child("sim", "--replay", str(output), "--link", str(link), log=replay_log) as sim:
        name, device = (await sim.readline()).split()
        assert (name, device) == ("north", str(link))
        requests = [request for request, _ in pairs]
        replies = [reply for _, reply in pairs]
        got = await asyncio.to_thread(_ask, device, requests, [len(r) for r in replies])
        assert got[:-2] == replies  # the same bytes, in the order they were captured
        assert got[-2] == b""
        assert got[-1] == b"\x02"  # a captured request is still answered after it
        served = [await sim.readline() for _ in range(len(pairs) + 2)]
        assert served[0] == f"north {requests[0].hex(' ')} -> {replies[0].hex(' ')}\n"
        assert served[-2] == "north 02 0e 07" + " 00" * 12 + " -> (no answer)\n"
        assert (await sim.stop())[0] == 0
    assert not link.exists()


async def test_replay_refuses_a_file_that_is_not_a_capture(tmp_path: Path) -> None:
    bogus = tmp_path / "bogus.pcapng"
    bogus.write_bytes(b"not pcapng at all, just text")
    log = tmp_path / "replay.log"
    async with child("sim", "--replay", str(bogus), log=log) as sim:
        code = await asyncio.wait_for(sim.process.wait(), START_S)
    assert code == 2
    assert "not a pcapng file" in log.read_text()
    with contextlib.suppress(FileNotFoundError):
        assert not (tmp_path / "ttyREPLAY").exists()


async def _tool(*args: str) -> tuple[int, str, str]:
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "fcmaster", *args,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    out, err = await asyncio.wait_for(process.communicate(), START_S)
    assert process.returncode is not None
    return process.returncode, out.decode(), err.decode()


async def test_the_commissioning_tools_get_what_a_daemons_capture_implies(tmp_path: Path) -> None:
    # Captured from a daemon commanding its drives (control: bus): the tools send control
    # word 0, and scan asks no parameter at all; neither is in the capture byte for byte.
    output = await _capture_a_running_line(tmp_path, control="bus")
    link = tmp_path / "ttyREPLAY"
    line = ("--port", str(link), "--baudrate", "38400")
    replay_log = tmp_path / "replay.log"
    async with child("sim", "--replay", str(output), "--link", str(link), log=replay_log) as sim:
        assert (await sim.readline()).split() == ["north", str(link)]
        code, out, err = await _tool("scan", *line, "--addresses", "1-3", "--json")
        assert code == 0, err
        found = {entry["address"]: entry for entry in json.loads(out)}
        assert sorted(found) == [1, 2]  # 3 was never on the line
        assert found[1]["running"]
        assert not found[2]["running"]
        code, out, err = await _tool("status", *line, "--address", "1", "--json")
        assert code == 0, err
        state = json.loads(out)
        assert state["running"]
        assert state["output_frequency_hz"] == pytest.approx(30.0, abs=0.5)
        assert state["values"]["16-14"]["unit"] == "A"
