"""The commissioning commands (`scan`, `status`, `read`, `control`) on a Modbus RTU line.

Each command runs as its own `python -m fcmaster` process against simulated drives of
several families served on a pseudo-terminal by the test's event loop, as a technician
would run them against a real line.
"""

from __future__ import annotations

import json
from contextlib import AbstractAsyncContextManager

from fcmaster.sim import DriveSettings, LineSettings, PtyServer
from tests.integration import commissioning

LINE = LineSettings(protocol="modbus-rtu", baudrate=19200, parity="E")
PROFILES = {1: "abb-drives", 2: "sinamics-v20", 4: "yaskawa-memobus"}
INSTANT = {"ramp_up_s": 0.0, "ramp_down_s": 0.0}  # at the reference by the next request


def served() -> AbstractAsyncContextManager[PtyServer]:
    return commissioning.served(
        LINE, [(a, DriveSettings(profile=p, parameters=INSTANT)) for a, p in PROFILES.items()]
    )


async def fcmaster(server: PtyServer, address: int, *args: str) -> tuple[int, str, str]:
    """``fcmaster args[0] --port PTY --protocol modbus-rtu --profile P --address N args[1:]``."""
    return await commissioning.fcmaster(
        server, "modbus-rtu", args[0], "--profile", PROFILES[address],
        "--address", str(address), *args[1:],
    )  # fmt: skip


async def run_in_reverse(server: PtyServer, address: int) -> str:
    """Start the drive at 20 Hz and reverse it: it turns at -20 Hz from its next request.

    What the start printed on stderr.
    """
    said = []
    for action in (("start", "--frequency", "20"), ("reverse",)):
        code, _, err = await fcmaster(server, address, "control", *action)
        assert code == 0, err
        said.append(err)
    return said[0]


async def test_status_of_a_drive_without_a_reverse_bit_tells_the_direction_by_the_sign() -> None:
    async with served() as server:
        await run_in_reverse(server, 2)  # a V20: its status word has no reverse bit
        code, out, err = await fcmaster(server, 2, "read", "hr23", "--json")
        assert code == 0, err
        assert json.loads(out)["value"] == -20.0  # r0024, signed
        code, out, err = await fcmaster(server, 2, "status", "--json")
    assert code == 0, err
    state = json.loads(out)
    assert (state["direction"], state["output_frequency_hz"]) == ("reverse", 20.0)


async def test_a_drive_with_an_unsigned_frequency_register_reads_it_in_reverse() -> None:
    async with served() as server:
        note = await run_in_reverse(server, 4)  # a Yaskawa: 0024H holds the magnitude
        # its watchdog is H5-09/H5-04/H5-05, not another protocol's parameters
        assert "yaskawa-memobus registers hr1077, hr1064, hr1065" in note
        assert "8-03" not in note
        code, out, err = await fcmaster(server, 4, "read", "hr36", "--json")
        assert code == 0, err
        assert json.loads(out)["value"] == 20.0
        code, out, err = await fcmaster(server, 4, "status", "--json")  # still answering
    assert code == 0, err
    assert json.loads(out)["running"] is True


async def test_scan_with_a_profile_says_which_drives_refused_its_status_read() -> None:
    scan = ("scan", "--profile", "abb-drives", "--addresses", "1-4")
    async with served() as server:
        code, out, err = await commissioning.fcmaster(server, "modbus-rtu", *scan)
        assert code == 0, err
        rows = {int(row.split()[0]): row for row in out.splitlines()}
        code, out, err = await commissioning.fcmaster(server, "modbus-rtu", *scan, "--json")
        assert code == 0, err
        # without a profile, only presence is asked (register 0, which the Yaskawa lacks)
        unprofiled = ("scan", "--addresses", "1-4")
        code, bare, err = await commissioning.fcmaster(server, "modbus-rtu", *unprofiled)
    assert code == 0, err
    assert [row.split(None, 1)[1] for row in bare.splitlines()] == [
        "answers (no status read: it needs a profile)"
    ] * 3
    assert sorted(rows) == [1, 2, 4]
    assert "status 0x" in rows[1]
    for address in (2, 4):  # another family's drive: no register 400004 (exception 02)
        assert "answers, but refused the status read" in rows[address]
        assert "needs a profile" not in rows[address]
    found = {entry["address"]: entry for entry in json.loads(out)}
    assert found[1]["running"] is False
    assert [found[a]["running"] for a in (2, 4)] == [None, None]
    assert [found[a]["status_word"] for a in (2, 4)] == [None, None]


async def test_status_through_another_familys_profile_says_the_drive_refused_it() -> None:
    async with served() as server:
        # Address 1 is an ABB drive; told it is an Altivar, its status read is refused.
        code, out, err = await commissioning.fcmaster(
            server, "modbus-rtu", "status", "--profile", "altivar-cia402", "--address", "1"
        )
    assert code == 1, out
    assert "refused the status read" in err
    assert "profile" in err
    assert "running" not in out  # no state that reads stopped and healthy
