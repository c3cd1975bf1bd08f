"""A Modbus RTU line captured over HTTP into pcapng that Wireshark dissects as Modbus RTU.

All real: `fcmaster sim` serves the line on a pty, `fcmaster run` polls it, `fcmaster
capture` follows the daemon's frame log. The file's packets are RTAC serial packets
(LINKTYPE_RTAC_SERIAL, 250) whose payload is the frame, and `tshark` decodes them as Modbus
RTU when told the payload's protocol (`-d rtacser.data,mbrtu`, Wireshark's "Decode As").
Without `tshark` the test is skipped, except under CI, where it fails (.ci/run installs it).
"""

from __future__ import annotations

import asyncio
import os
import shutil
import signal
import struct
from pathlib import Path
from typing import Any

import httpx
import pytest

from fcmaster.protocol import pcapng
from fcmaster.protocol.modbus_rtu import decode_request, decode_response
from tests.integration.daemon_harness import START_S, by_name, child, get_json, until
from tests.integration.ports import free_port

VIEWER = "viewer-token-0123456789abcdef"
CONFIG = """
buses:
  - name: rtu
    port: {port_path}
    protocol: modbus-rtu
    baudrate: 38400
    drives:
      - {{name: abb, address: 1, profile: abb-drives}}
      - {{name: altivar, address: 3, profile: altivar-cia402}}
http:
  listen: 127.0.0.1:{port}
  tokens:
    - {{name: scada, role: viewer, token: {viewer}}}
"""


def tshark() -> str:
    """The path of ``tshark``; skips without it, fails under CI (.ci/run installs it)."""
    path = shutil.which("tshark")
    if path is None:
        if os.environ.get("CI") == "true":
            pytest.fail("tshark is not installed (apt-get install tshark; .ci/run does it)")
        pytest.skip("needs tshark (apt package tshark)")
    return path


def first_packet_bytes(data: bytes) -> bytes:
    """The bytes of the file's first Enhanced Packet Block, as stored (little-endian file)."""
    offset = 0
    while offset < len(data):
        kind, length = struct.unpack_from("<II", data, offset)
        if kind == pcapng.EPB:
            (captured,) = struct.unpack_from("<I", data, offset + 20)
            return data[offset + 28 : offset + 28 + captured]
        offset += length
    raise AssertionError("no packet in the file")


async def _capture(tmp_path: Path) -> Path:
    port_path, port = tmp_path / "ttyRTU", free_port()
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG.format(port_path=port_path, port=port, viewer=VIEWER))
    output = tmp_path / "rtu.pcapng"
    url = f"http://127.0.0.1:{port}"
    async with child("sim", "--config", str(config), log=tmp_path / "sim.log") as sim:
        assert (await sim.readline()).split()[0] == "rtu"
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
            args = ("capture", "--url", url, "--bus", "rtu", "--seconds", "1")
            log = tmp_path / "capture.log"
            async with child(*args, "-o", str(output), "--token", VIEWER, log=log) as cap:
                assert await asyncio.wait_for(cap.process.wait(), START_S + 5) == 0, cap.tail()
            assert (await daemon.stop(signal.SIGTERM))[0] == 0
        assert (await sim.stop())[0] == 0
    return output


async def test_a_modbus_rtu_capture_is_rtac_serial_that_tshark_decodes_as_modbus(
    tmp_path: Path,
) -> None:
    output = await _capture(tmp_path)
    data = output.read_bytes()
    capture = pcapng.decode(data)
    (interface,) = capture.interfaces
    assert interface.link_type == pcapng.RTAC_SERIAL == 250
    assert interface.description == "modbus-rtu 38400 8E1"
    packets = capture.packets
    assert len(packets) > 20
    # stored: the RTAC serial header (its time in big-endian seconds and microseconds, the
    # event: 1 sent, 2 received), then the frame as it was on the wire
    stored = first_packet_bytes(data)
    seconds, micros, event, lines, footer = struct.unpack_from(">IIBBH", stored)
    first = packets[0]
    assert seconds * 1_000_000 + micros == first.timestamp_us
    assert (event, lines, footer) == (1 if first.direction == pcapng.OUTBOUND else 2, 0, 0)
    assert stored[12:] == first.data
    requests = [decode_request(p.data) for p in packets if p.direction == pcapng.OUTBOUND]
    answers = [decode_response(p.data) for p in packets if p.direction == pcapng.INBOUND]
    assert {r.address for r in requests} == {r.address for r in answers} == {1, 3}

    process = await asyncio.create_subprocess_exec(
        tshark(), "-r", str(output), "-d", "rtacser.data,mbrtu",
        "-o", "mbrtu.crc_verification:TRUE",
        "-T", "fields", "-E", "separator=,", "-e", "rtacser.eventtype", "-e", "mbrtu.unit_id",
        "-e", "modbus.func_code", "-e", "mbrtu.crc16.status",
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    out, err = await process.communicate()
    assert process.returncode == 0, err.decode()
    rows = [line.split(",") for line in out.decode().splitlines()]
    assert len(rows) == len(packets)
    # every packet: its direction's event, the drive's address, read holding registers (a
    # monitor-only line polls and writes nothing), and a good CRC
    assert [(row[0], row[1], row[2]) for row in rows] == [
        ("0x01" if p.direction == pcapng.OUTBOUND else "0x02", str(p.data[0]), "3") for p in packets
    ]
    assert {row[3] for row in rows} == {"1"}  # 1: good
