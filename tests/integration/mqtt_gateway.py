"""The fleet MQTT tests script: two lines of the shared gateway double, and a gate that
holds commands until the test lets them finish."""

from __future__ import annotations

import asyncio
from typing import Any

from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.clock import Clock
from tests.integration import gateway_double
from tests.integration.gateway_double import Respond, done

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


class FakeGateway(gateway_double.FakeGateway):
    """The shared gateway double over :data:`LINES`."""

    def __init__(self, respond: Respond = done, *, clock: Clock | None = None) -> None:
        super().__init__(LINES, respond, clock=clock)


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
