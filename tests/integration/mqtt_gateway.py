"""A Gateway for MQTT tests that need control of the fleet: a real hub and fleet state fed
with replies by the test, and an ``execute`` the test scripts (it records every call, so a
test can tell that nothing reached a line)."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any

from fcmaster.adapters.gateway import LineInfo
from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import MonotonicClock
from fcmaster.hub import Hub
from fcmaster.protocol.codec import (
    Condition,
    ConditionReport,
    DriveStatus,
    ParameterKey,
    ParameterValue,
    Reply,
)
from fcmaster.state import FleetState

Handler = Callable[[str, Command], Awaitable[CommandResult]]

LINES = (
    LinePlan(
        name="line1",
        port="sim://line1",
        drives=(
            DrivePlan(name="pump-1", address=1, control=True, max_frequency_hz=50.0),
            DrivePlan(name="fan-2", address=2),
        ),
    ),
    LinePlan(name="line2", port="sim://line2", drives=(DrivePlan(name="mixer-3", address=3),)),
)


async def done(drive: str, command: Command) -> CommandResult:
    return CommandResult(outcome=Outcome.DONE)


class FakeGateway:
    """Meets :class:`fcmaster.adapters.gateway.Gateway`."""

    def __init__(self, lines: tuple[LinePlan, ...] = LINES, handler: Handler = done) -> None:
        self.plans = lines
        self.clock = MonotonicClock()
        self.hub = Hub()
        self.fleet = FleetState(lines, emit=self.hub.publish, clock=self.clock)
        self.handler = handler
        self.executed: list[tuple[str, Command]] = []

    def drive_plan(self, name: str) -> DrivePlan | None:
        return next((d for line in self.plans for d in line.drives if d.name == name), None)

    def lines(self) -> list[LineInfo]:
        return [
            LineInfo(
                name=line.name, port=line.port, protocol=line.protocol, baudrate=line.baudrate,
                up=True, drives=tuple(d.name for d in line.drives), stats={},
            )
            for line in self.plans
        ]  # fmt: skip

    async def execute(self, drive: str, command: Command) -> CommandResult:
        self.executed.append((drive, command))
        return await self.handler(drive, command)

    # -- feeding the fleet state, as a BusMaster would -------------------------------------

    def _where(self, drive: str) -> tuple[str, DrivePlan]:
        for line in self.plans:
            for plan in line.drives:
                if plan.name == drive:
                    return line.name, plan
        raise KeyError(drive)

    def reply(
        self,
        drive: str,
        *,
        running: bool = False,
        frequency_hz: float | None = None,
        value: tuple[str, float, str] | None = None,
        alarms: tuple[Condition, ...] | None = None,
    ) -> None:
        """The drive answered a poll."""
        bus, plan = self._where(drive)
        status = DriveStatus(
            word=0x0B07 if running else 0x0607, running=running, fault=bool(alarms),
            warning=False, at_reference=running,
        )  # fmt: skip
        parameter_value = None
        if value is not None:
            name, number, unit = value
            key = ParameterKey(name=name, code=int(name.replace("-", "")))
            parameter_value = ParameterValue(
                parameter=key, index=0, raw=int(number * 10), value=number, unit=unit
            )
        conditions = None
        if alarms is not None:
            conditions = ConditionReport(kind="alarm", source="16-90", active=alarms)
        reply = Reply(
            address=plan.address, status=status, output_frequency_hz=frequency_hz,
            value=parameter_value, conditions=conditions,
        )  # fmt: skip
        self.fleet.drive_replied(bus, plan, reply, self.clock.now(), None)

    def offline(self, drive: str) -> None:
        """The drive stopped answering."""
        bus, plan = self._where(drive)
        self.fleet.drive_availability(bus, plan, False, self.clock.now())


class Gate:
    """A handler that holds each command until the test releases it."""

    def __init__(self, result: CommandResult | None = None) -> None:
        self.result = result or CommandResult(outcome=Outcome.DONE)
        self.open: dict[Any, asyncio.Event] = {}
        self.arrived: asyncio.Queue[tuple[str, Command]] = asyncio.Queue()

    def release(self, drive: str, action: str) -> None:
        self.open.setdefault((drive, action), asyncio.Event()).set()

    async def __call__(self, drive: str, command: Command) -> CommandResult:
        await self.arrived.put((drive, command))
        await self.open.setdefault((drive, command.action.value), asyncio.Event()).wait()
        return self.result
