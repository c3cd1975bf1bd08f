"""Hardware faults on a served pty, met by the commissioning tools as real processes: a
master at the wrong baud rate, two drives on one address, a USB adapter's latency timer."""

from __future__ import annotations

import json
from pathlib import Path

from fcmaster.sim import DriveSettings, LineSettings, PtyServer
from tests.integration import commissioning

FC_19200 = LineSettings(protocol="danfoss-fc", baudrate=19200, parity="E")


async def scan(server: PtyServer, *args: str) -> tuple[int, list[int], str]:
    code, out, err = await commissioning.fcmaster(
        server, "danfoss-fc", "scan", "--addresses", "1-3", "--timeout", "0.1", "--json", *args
    )
    found = [entry["address"] for entry in json.loads(out)] if code == 0 else []
    return code, found, err


async def test_a_scan_at_the_wrong_baud_rate_finds_nothing_and_at_the_right_one_finds_it() -> None:
    async with commissioning.served(FC_19200, [(2, DriveSettings())]) as server:
        code, found, _ = await scan(server, "--baudrate", "9600")
        assert (code, found) == (1, [])
        assert server.line.counters.misframed_bytes > 0  # the sim read the client's speed
        assert server.line.counters.requests == 0
        code, found, err = await scan(server, "--baudrate", "19200")
        assert (code, found) == (0, [2]), err


async def test_two_drives_on_one_address_collide_and_neither_is_found() -> None:
    line = LineSettings(protocol="danfoss-fc", baudrate=19200, duplicate_addresses=True)
    async with commissioning.served(line, [(1, DriveSettings()), (1, DriveSettings())]) as server:
        code, found, _ = await scan(server, "--baudrate", "19200")
        assert (code, found) == (1, [])
        assert server.line.counters.collisions >= 1
        assert server.line.counters.replies >= 2


async def test_replies_held_by_an_adapter_still_arrive() -> None:
    line = LineSettings(protocol="danfoss-fc", baudrate=19200, adapter_latency_ms=16)
    async with commissioning.served(line, [(3, DriveSettings())]) as server:
        code, found, err = await scan(server, "--baudrate", "19200")
        assert (code, found) == (0, [3]), err
        assert server.line.adapter is not None
        assert server.line.adapter.chunks >= 1


async def test_fcmaster_sim_serves_an_adapter_latency_and_twins(tmp_path: Path) -> None:
    twins = ("--addresses", "1,2,2", "--duplicate-addresses", "--adapter-latency-ms", "16")
    name, found = await commissioning.scan_a_served_sim(
        tmp_path,
        (*twins, "--baudrate", "19200"),
        ("--addresses", "1-3", "--baudrate", "19200", "--timeout", "0.1"),
    )
    assert name == "line1"
    assert found == [1]  # 2's two drives garble each other


async def test_a_rate_termios_has_no_constant_for_is_heard_at_its_own_speed() -> None:
    # 76800 (FC 8-32 offers it) is set as BOTHER with the number beside it: the server reads
    # the number, so a master at 76800 is misframed on a 19200 line and heard on a 76800 one.
    async with commissioning.served(FC_19200, [(2, DriveSettings())]) as server:
        code, found, _ = await scan(server, "--baudrate", "76800")
        assert (code, found) == (1, [])
        assert server.line.counters.misframed_bytes > 0
    line = LineSettings(protocol="danfoss-fc", baudrate=76800, parity="E")
    async with commissioning.served(line, [(2, DriveSettings())]) as server:
        code, found, err = await scan(server, "--baudrate", "76800")
        assert (code, found) == (0, [2]), err
