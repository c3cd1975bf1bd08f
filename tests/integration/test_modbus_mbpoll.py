"""The Modbus server through ``mbpoll``, a Modbus client from Debian written in C."""

from __future__ import annotations

import asyncio
import re

import pytest

from tests.integration.modbus_client import mbpoll
from tests.integration.modbus_harness import Plant, plant
from tests.integration.waiting import wait_for

LIMIT_S = 30.0


async def run_mbpoll(running: Plant, *args: str) -> tuple[int, str]:
    """``mbpoll`` once against the plant's server, PDU addressing; exit code and output."""
    process = await asyncio.create_subprocess_exec(
        mbpoll(), "-m", "tcp", "-p", str(running.port), "-0", "-1", "-o", "5", *args,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT,
    )  # fmt: skip
    output, _ = await process.communicate()
    return await process.wait(), output.decode(errors="replace")


def values(output: str) -> dict[int, str]:
    """``[address]: value`` lines of mbpoll's output."""
    return {int(a): v for a, v in re.findall(r"^\[(\d+)\]:\s+(\S+)", output, re.MULTILINE)}


async def test_mbpoll_reads_the_drive_and_starts_it_with_a_reference() -> None:
    async with asyncio.timeout(LIMIT_S), plant() as running:
        drive = running.drive("line1", 1)
        code, output = await run_mbpoll(running, "-a", "1", "-t", "3", "-r", "0", "-c", "14",
                                        "127.0.0.1")  # fmt: skip
        assert code == 0, output
        words = values(output)
        assert (words[0], words[2], words[3]) == ("1", str(drive.control.status_word), "0")

        code, output = await run_mbpoll(running, "-a", "1", "-t", "4", "-r", "0", "127.0.0.1",
                                        "1", "2000")  # fmt: skip
        assert code == 0, output
        assert drive.control.reference_pct == pytest.approx(40.0, abs=0.01)  # 20 Hz of 50
        await wait_for(lambda: drive.motor.frequency_hz > 5.0)

        async def frequency_shows() -> None:
            while True:
                code, output = await run_mbpoll(
                    running, "-a", "1", "-t", "3:float", "-B", "-r", "16", "127.0.0.1"
                )
                assert code == 0, output
                if float(values(output)[16]) > 5.0:
                    return

        await asyncio.wait_for(frequency_shows(), 10)  # 16-13, an f32 high word first


async def test_mbpoll_sees_the_exceptions_of_refused_writes() -> None:
    async with asyncio.timeout(LIMIT_S), plant() as running:
        code, output = await run_mbpoll(running, "-a", "1", "-t", "4", "-r", "1", "127.0.0.1",
                                        "4500")  # fmt: skip  # 45 Hz, beyond pump-1's 40 Hz
        assert code != 0
        assert "Illegal data value" in output
        code, output = await run_mbpoll(running, "-a", "9", "-t", "3", "-r", "0", "127.0.0.1")
        assert code != 0
        assert "Gateway path unavailable" in output
        assert running.drive("line1", 1).control.reference_pct == 0.0
