"""The real BusMaster and SerialTransport against simulated FC drives on a pseudo-terminal.

Everything below the master is real: termios, the pty, the simulator's wire timing and its
injected faults. The simulator runs in the same event loop as the master here, which is
slower than a real line but changes no behaviour.
"""

import asyncio
from collections.abc import AsyncIterator
from contextlib import ExitStack, asynccontextmanager
from pathlib import Path
from typing import Any

import pytest

from fcmaster.bus.commands import Action, Command, Outcome
from fcmaster.bus.master import BACKOFF_MAX_S, BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.sim.build import build_line
from fcmaster.sim.danfoss_fc.drive import FcSimDrive
from fcmaster.sim.faults import FaultPlan
from fcmaster.sim.pty import PtyServer
from fcmaster.sim.settings import DriveSettings, LineSettings
from fcmaster.transport.serial import SerialTransport
from tests.integration.line_checks import assert_faults_counted_and_no_command_lost
from tests.integration.tcp_bridge import TcpBridge, tcp_bridge
from tests.integration.waiting import wait_for
from tests.orders import orders

LIMIT_S = 30.0
ADDRESSES = (1, 2, 3, 4)


@asynccontextmanager
async def line_with_master(
    faults: FaultPlan,
    *,
    baudrate: int = 38400,
    drive_faults: dict[int, FaultPlan] | None = None,
    over: str | None = None,
    bridges: list[TcpBridge] | None = None,
) -> AsyncIterator[tuple[PtyServer, BusMaster]]:
    """A master on a simulated line: on its pty, or ``over`` a TCP bridge (socket, rfc2217).

    The bridge is appended to ``bridges`` when one is given.
    """
    clock = MonotonicClock()
    own = drive_faults or {}
    line = build_line(
        LineSettings(baudrate=baudrate, faults=faults),
        [(a, DriveSettings(response_delay_s=0.005, faults=own.get(a))) for a in ADDRESSES],
        clock=clock,
    )
    drives = tuple(
        DrivePlan(name=f"d{a}", address=a, control=a == 1, monitor=("16-13", "16-14"))
        for a in ADDRESSES
    )
    async with asyncio.timeout(LIMIT_S), PtyServer(line, clock=clock) as server:
        stack = ExitStack()
        port = server.device
        if over is not None:
            bridge = stack.enter_context(
                tcp_bridge(
                    server.device,
                    rfc2217=over == "rfc2217",
                    # a raw bridge is set to the line's rate; RFC 2217 must set it itself
                    baudrate=baudrate if over == "socket" else 19200,
                )
            )
            if bridges is not None:
                bridges.append(bridge)
            port = bridge.url
        plan = LinePlan(
            name="pty",
            port=port,
            baudrate=baudrate,
            # a pty takes no parity; over RFC 2217 the format is set on the bridge's pty
            parity="E" if over is None else "N",
            drives=drives,
            offline_after=5,
            probe_interval_s=0.5,
            response_delay_s=0.005,
        )
        transport = SerialTransport(plan.port, baudrate=baudrate, parity=plan.parity)
        with stack:
            async with BusMaster(plan, codec=FcCodec(), transport=transport, clock=clock) as master:
                yield server, master


async def test_every_drive_is_polled_and_a_command_turns_the_motor() -> None:
    async with line_with_master(FaultPlan()) as (server, master):
        await wait_for(lambda: all(s.online for s in master.planner.slots))
        result = await orders(master, "d1").start(frequency_hz=25.0)
        assert result.outcome is Outcome.DONE
        drive = next(d for d in server.line.drives if d.address == 1)
        assert isinstance(drive, FcSimDrive)
        await wait_for(lambda: drive.motor.frequency_hz > 20.0)  # ramping up on the sim side
        read = await orders(master, "d1").read("16-13")
        assert read.outcome is Outcome.DONE
        assert read.value is not None
        assert 0.0 < float(read.value.value) <= 25.0
        stats = master.stats
        # The simulator shares the master's loop: on a loaded machine a reply can come after
        # its deadline. It must then show up late (discarded before the next request, or
        # taken for no one's), never be lost or garbled.
        assert stats.timeouts * 16 <= stats.late_bytes + 16 * stats.unexpected, stats
        assert master.stats.checksum_errors == 0


async def test_faults_are_counted_and_no_command_is_lost() -> None:
    faults = FaultPlan(drop=0.05, corrupt=0.05, noise=0.05, seed=3)
    async with line_with_master(faults) as (server, master):
        await wait_for(lambda: master.stats.replies >= 300, timeout_s=20.0)
        results = await asyncio.gather(
            *(orders(master, f"d{a}").read("16-14") for a in ADDRESSES for _ in range(5))
        )
        counters = server.line.counters
    assert_faults_counted_and_no_command_lost(
        results, master.stats, counters, commands=20, at_least_done=15
    )
    assert master.stats.malformed == 0


async def test_a_silent_drive_is_demoted_probed_and_promoted_again() -> None:
    silent = {2: FaultPlan(silent_periods=((0.5, 2.0),))}  # drive 2 only, 0.5 s to 2 s in
    async with line_with_master(FaultPlan(seed=1), drive_faults=silent) as (_, master):
        slot = master.planner.slot("d2")
        await wait_for(lambda: slot.online is False, timeout_s=5.0)
        assert master.planner.slot("d3").online  # the others are still polled
        await wait_for(lambda: slot.online is True, timeout_s=8.0)


@pytest.mark.parametrize("over", ["socket", "rfc2217"])
async def test_a_line_served_over_tcp_is_polled_and_commanded(over: str) -> None:
    """Serial device servers: a raw TCP bridge (socket://) and RFC 2217 (rfc2217://)."""
    bridges: list[TcpBridge] = []
    async with line_with_master(FaultPlan(), over=over, bridges=bridges) as (server, master):
        await wait_for(lambda: all(s.online for s in master.planner.slots))
        result = await orders(master, "d1").start(frequency_hz=25.0)
        assert result.outcome is Outcome.DONE
        drive = next(d for d in server.line.drives if d.address == 1)
        assert isinstance(drive, FcSimDrive)
        await wait_for(lambda: drive.motor.frequency_hz > 20.0)
        read = await orders(master, "d1").read("16-13")
        assert read.outcome is Outcome.DONE
        assert read.value is not None
        assert 0.0 < float(read.value.value) <= 25.0
        assert master.stats.checksum_errors == 0
        (bridge,) = bridges
        if over == "rfc2217":  # the client set the line's format on the server's port
            assert (38400, "N") in bridge.settings_seen
        # The device server restarts: the line goes down, comes back, and serves again.
        replies = master.stats.replies
        bridge.drop_client()
        await wait_for(lambda: master.stats.reopens >= 1 and master.is_up, timeout_s=10.0)
        await wait_for(lambda: master.stats.replies > replies + 20, timeout_s=10.0)
        assert bridge.clients == 2


async def test_an_adapter_plugged_back_in_is_opened_at_once_not_after_the_backoff(
    tmp_path: Path,
) -> None:
    clock = MonotonicClock()
    line = build_line(
        LineSettings(baudrate=38400), [(1, DriveSettings(response_delay_s=0.005))], clock=clock
    )
    node = tmp_path / "ttyUSB0"
    plan = LinePlan(
        name="usb",
        port=str(node),
        baudrate=38400,
        drives=(DrivePlan(name="d1", address=1),),
        response_delay_s=0.005,
    )
    transport = SerialTransport(plan.port, baudrate=38400, parity=plan.parity)
    master = BusMaster(plan, codec=FcCodec(), transport=transport, clock=clock)
    async with asyncio.timeout(LIMIT_S), PtyServer(line, clock=clock) as server, master:
        await asyncio.sleep(3.0)  # the node is missing: the backoff has grown to seconds
        assert not master.is_up
        assert "cannot open" in (master.stats.down_reason or "")
        node.symlink_to(server.device)  # plugged in
        plugged = clock.now()
        await wait_for(lambda: master.is_up, timeout_s=BACKOFF_MAX_S)
        opened_after = clock.now() - plugged
        await wait_for(lambda: master.planner.slot("d1").online, timeout_s=5.0)
    assert opened_after < 0.5


async def test_a_bug_met_while_polls_run_in_callbacks_restarts_the_line_like_one_in_its_loop(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Steady polling runs in the port's reader callback and in timers: what it raises must
    # still reach the master's supervision (logged, the line restarted), not the event
    # loop's exception handler, where it would be printed and the line would hang.
    async with line_with_master(FaultPlan()) as (_, master):
        await wait_for(lambda: master.stats.replies >= 20)
        on_reply = master.planner.on_reply
        raised: list[int] = []

        def broken(*args: Any, **kwargs: Any) -> Any:
            if not raised:
                raised.append(1)
                raise RuntimeError("a bug in the planner")
            return on_reply(*args, **kwargs)

        monkeypatch.setattr(master.planner, "on_reply", broken)
        await wait_for(lambda: master.stats.crashes == 1, timeout_s=5.0)
        await wait_for(lambda: master.is_up, timeout_s=10.0)
        replies = master.stats.replies
        await wait_for(lambda: master.stats.replies >= replies + 20, timeout_s=10.0)
        result = await master.execute("d1", Command(action=Action.READ, parameter="16-13"))
        assert result.outcome is Outcome.DONE
