"""The daemon as an adapter sees it, for adapter tests that script the fleet.

Real parts — a Hub, a FleetState and LineStats — with an ``execute()`` the test controls
(every call is recorded, so a test can tell that nothing reached a line). Drive replies are
folded into the fleet state exactly as a BusMaster reports them, through
``FleetState.drive_replied``.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

from fcmaster.adapters.gateway import LineInfo
from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.bus.frame_log import FrameLog, FramesSince
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.bus.stats import LineStats
from fcmaster.clock import Clock, MonotonicClock
from fcmaster.hub import Hub
from fcmaster.protocol.codec import (
    Condition,
    ConditionReport,
    DriveStatus,
    ParameterKey,
    ParameterValue,
    Reply,
)
from fcmaster.protocol.drive import ControlIntent
from fcmaster.state import FleetState

PUMP = DrivePlan(
    name="pump-1", address=1, control=True, nominal_frequency_hz=50.0, max_frequency_hz=50.0
)
FAN = DrivePlan(name="fan-1", address=2)
# The manual's names of the FC parameters these tests use, as the codec's table gives them.
FC_NAMES = {"16-14": "Motor Current", "16-30": "DC Link Voltage", "16-12": "Motor Voltage"}
LINE = LinePlan(name="line1", port="sim://line1", drives=(PUMP, FAN))

Respond = Callable[[str, Command], CommandResult | Awaitable[CommandResult]]


def done(_drive: str, _command: Command) -> CommandResult:
    """Every command is carried out."""
    return CommandResult(outcome=Outcome.DONE)


class FakeGateway:
    """The daemon as an adapter sees it, built from a Hub, a FleetState and LineStats."""

    def __init__(
        self,
        lines: tuple[LinePlan, ...] = (LINE,),
        respond: Respond = done,
        *,
        clock: Clock | None = None,
    ) -> None:
        self.plans = lines
        self.clock = clock or MonotonicClock()
        self.hub = Hub()
        self.fleet = FleetState(lines, emit=self.hub.publish, clock=self.clock)
        self.stats = {line.name: LineStats(up_since=self.clock.now()) for line in lines}
        self.up = {line.name: True for line in lines}
        self.adapters: dict[str, dict[str, Any]] = {}  # the USB adapter a line's port is on
        self.respond = respond
        self.executed: list[tuple[str, Command]] = []
        self.frames: dict[str, FrameLog] = {}  # what each line's link would have logged

    def drive_plan(self, name: str) -> DrivePlan | None:
        for line in self.plans:
            for drive in line.drives:
                if drive.name == name:
                    return drive
        return None

    def lines(self) -> list[LineInfo]:
        now = self.clock.now()
        return [
            LineInfo(
                name=line.name,
                port=line.port,
                protocol=line.protocol,
                baudrate=line.baudrate,
                up=self.up[line.name],
                drives=tuple(d.name for d in line.drives),
                stats=self.stats[line.name].to_json(now),
                adapter=self.adapters.get(line.name),
            )
            for line in self.plans
        ]

    def line_frames(self, name: str, since: int) -> tuple[LinePlan, FramesSince] | None:
        for line in self.plans:
            if line.name == name:
                return line, self.frames.setdefault(name, FrameLog(self.clock.wall)).since(since)
        return None

    def config_status(self) -> dict[str, Any]:
        return {"hash": "0" * 16, "loaded_at": None, "last_reload": None, "reloads": {}}

    def opcua_status(self) -> dict[str, Any] | None:
        return None

    async def events(
        self,
        *,
        since: float | None = None,
        kind: str | None = None,
        drive: str | None = None,
        limit: int = 100,
    ) -> list[dict[str, Any]]:
        return []

    async def execute(self, drive: str, command: Command) -> CommandResult:
        self.executed.append((drive, command))
        result = self.respond(drive, command)
        if isinstance(result, CommandResult):
            return result
        return await result

    # -- what the bus would report ---------------------------------------------------------

    def _line_of(self, name: str) -> tuple[str, DrivePlan]:
        for line in self.plans:
            for drive in line.drives:
                if drive.name == name:
                    return line.name, drive
        raise KeyError(name)

    def reply(
        self,
        name: str,
        *,
        running: bool = False,
        hz: float | None = None,
        warning: bool = False,
        value: tuple[str, float | str, str] | None = None,
        alarms: tuple[tuple[int, str], ...] | None = None,
        warnings: tuple[tuple[int, str], ...] | None = None,
    ) -> None:
        """One reply from drive ``name``, folded in as the BusMaster would."""
        bus, plan = self._line_of(name)
        fault = bool(alarms)
        status = DriveStatus(
            word=0x0607 | (0x0800 if running else 0) | (0x0008 if fault else 0),
            running=running,
            fault=fault,
            warning=warning or bool(warnings),
            at_reference=running,
        )
        parameter_value = None
        if value is not None:
            param, number, unit = value
            raw = int(number * 10) if isinstance(number, float) else None
            parameter_value = ParameterValue(
                parameter=ParameterKey(param, 0),
                index=0,
                raw=raw,
                value=number,
                unit=unit,
                title=FC_NAMES.get(param, ""),
            )
        reference = (hz or 0.0) / plan.nominal_frequency_hz * 100.0 if running else 0.0
        intent = ControlIntent(reference_pct=round(reference, 1)) if plan.control else None
        now = self.clock.now()
        self.fleet.drive_replied(
            bus,
            plan,
            Reply(
                address=plan.address, status=status, output_frequency_hz=hz, value=parameter_value
            ),
            now,
            intent,
        )
        for kind, conditions in (("alarm", alarms), ("warning", warnings)):
            if conditions is not None:
                report = ConditionReport(
                    kind=kind,
                    source="16-90" if kind == "alarm" else "16-92",
                    active=tuple(Condition(code, text) for code, text in conditions),
                )
                self.fleet.drive_replied(
                    bus, plan, Reply(address=plan.address, conditions=report), now, intent
                )

    def offline(self, name: str) -> None:
        """Drive ``name`` stopped answering."""
        bus, plan = self._line_of(name)
        self.fleet.drive_availability(bus, plan, False, self.clock.now())
