"""The adapter check on a real open: once per open, with the port's descriptor, and its
finding shown on the line (a pty has no adapter, so the finding is stood in for)."""

from __future__ import annotations

import asyncio
import os
from pathlib import Path

import pytest

from fcmaster.clock import MonotonicClock
from fcmaster.config import parse
from fcmaster.service import Service
from fcmaster.sim import DriveSettings, LineSettings, PtyServer, build_line
from fcmaster.transport import serial as serial_module
from fcmaster.transport.serial import SerialTransport
from fcmaster.transport.usb import Adapter

FTDI = Adapter(
    device="/dev/ttyUSB0", driver="ftdi_sio", by_id="/dev/serial/by-id/usb-FTDI-port0",
    by_path=None, latency_ms=16, low_latency=False,
)  # fmt: skip

CONFIG = """
buses:
  - name: north
    port: {port}
    baudrate: 19200
    drives:
      - {{name: pump-1, address: 1}}
"""


async def test_a_pty_has_no_adapter(tmp_path: Path) -> None:
    controller, device = os.openpty()
    try:
        transport = SerialTransport(os.ttyname(device), baudrate=19200)
        await transport.open()
        try:
            assert transport.adapter is None  # the real sysfs knows no adapter behind a pty
        finally:
            await transport.close()
    finally:
        os.close(controller)
        os.close(device)


async def test_the_adapter_found_at_open_is_shown_on_its_line(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    asked: list[tuple[str, bool]] = []

    def found(port: str, fd: int) -> Adapter:
        asked.append((port, os.isatty(fd)))
        return FTDI

    monkeypatch.setattr(serial_module, "tune", found)
    clock = MonotonicClock()
    line = build_line(LineSettings(baudrate=19200), [(1, DriveSettings())], clock=clock)
    async with PtyServer(line, clock=clock) as server:
        service = Service(parse(CONFIG.format(port=server.device)))
        runner = asyncio.create_task(service.run(install_signals=False))
        try:
            await service.hub.wait_for(lambda: service.lines()[0].up, timeout_s=20)
            [shown] = service.lines()
        finally:
            service.stop()
            await asyncio.wait_for(runner, 10)
    assert asked == [(server.device, True)]  # once, on the open port's descriptor
    assert shown.adapter == FTDI.to_json()
    assert shown.to_json()["adapter"]["latency_ms"] == 16
