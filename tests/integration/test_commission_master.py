"""`status` and `control` run the daemon's own BusMaster on the port they open.

In-process, against a simulated Danfoss FC drive on a pseudo-terminal: the command is the
master's (its audit line says so), and a status is one round of the master's polls.
"""

from __future__ import annotations

import json
from datetime import datetime

import pytest
import structlog

from fcmaster.errors import BusError
from fcmaster.sim import DriveSettings, FcSimDrive, LineSettings
from fcmaster.subcommands import commission
from tests.integration import commissioning

LINE = LineSettings(protocol="danfoss-fc", baudrate=38400, parity="E")
# The FC protocol's default monitor list (DESIGN.md's config example), read in this order.
MONITOR = ["16-13", "16-14", "16-12", "16-10", "16-30", "16-90", "16-92"]


def options(device: str) -> commission.LineOptions:
    return commission.LineOptions(port=device, baudrate=38400)


async def test_control_is_carried_and_audited_by_the_bus_master() -> None:
    async with commissioning.served(LINE, [(1, DriveSettings())]) as server:
        (drive,) = server.line.drives
        assert isinstance(drive, FcSimDrive)
        with structlog.testing.capture_logs() as logs:
            code = await commission.control(
                options(server.device), 1, "start", frequency_hz=25.0, reference_pct=None,
                nominal_frequency_hz=50.0, max_frequency_hz=None,
            )  # fmt: skip
        assert code == 0
        assert drive.control.reference_hz == 25.0
        assert drive.motor.output_on
    audits = [entry for entry in logs if entry["event"] == "command.completed"]
    assert [
        {k: entry[k] for k in ("bus", "drive", "actor", "command", "frequency_hz", "outcome")}
        for entry in audits
    ] == [
        {"bus": "cli", "drive": "drive-1", "actor": "cli", "command": "start",
         "frequency_hz": 25.0, "outcome": "done"},
    ]  # fmt: skip


async def test_status_is_one_round_of_the_masters_polls(
    capsys: pytest.CaptureFixture[str],
) -> None:
    running = DriveSettings(running_hz=30.0)
    async with commissioning.served(LINE, [(1, running)]) as server:
        before = server.line.counters.requests
        with structlog.testing.capture_logs():  # stdout holds the JSON alone
            assert await commission.status(options(server.device), 1, as_json=True) == 0
        heard = server.line.counters.requests - before
    state = json.loads(capsys.readouterr().out)
    assert (state["bus"], state["name"], state["online"]) == ("cli", "drive-1", True)
    assert state["running"] is True
    assert state["values"]["16-13"]["value"] == 30.0
    assert list(state["values"]) == MONITOR
    times = [datetime.fromisoformat(state["values"][p]["updated_at"]) for p in MONITOR]
    assert times == sorted(times)  # one poll each, in the monitor list's order
    # One round, plus the poll whose writing hands the last reply on, plus at most the one
    # in flight when the master was closed.
    assert len(MONITOR) <= heard <= len(MONITOR) + 2


async def test_status_of_a_silent_address_asks_each_item_once_then_says_so() -> None:
    async with commissioning.served(LINE, [(1, DriveSettings())]) as server:
        before = server.line.counters.requests
        with pytest.raises(BusError, match=f"no reply from address 5 on {server.device}"):
            await commission.status(options(server.device), 5, as_json=True)
        heard = server.line.counters.requests - before
    assert heard == len(MONITOR)  # demoted after a whole round, never probed
