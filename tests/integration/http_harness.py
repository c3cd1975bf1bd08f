"""A Gateway of real parts (Hub, FleetState, LineStats) with an execute() the test controls,
and the HTTP adapter served on 127.0.0.1 with an ephemeral port.

Drive replies are folded into the fleet state exactly as a BusMaster reports them, through
``FleetState.drive_replied``; commands end with whatever ``respond`` returns.
"""

from __future__ import annotations

import asyncio
import socket
import threading
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from typing import Any

import httpx

from fcmaster import config
from fcmaster.adapters.gateway import LineInfo
from fcmaster.adapters.http import HttpAdapter
from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.bus.stats import LineStats
from fcmaster.clock import MonotonicClock
from fcmaster.config import HttpModel, TokenModel
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
from fcmaster.service import Service
from fcmaster.state import FleetState

OPERATOR_TOKEN = "operator-secret-0123456789"
VIEWER_TOKEN = "viewer-secret-0123456789ab"
OPERATOR = {"Authorization": f"Bearer {OPERATOR_TOKEN}"}
VIEWER = {"Authorization": f"Bearer {VIEWER_TOKEN}"}

PUMP = DrivePlan(
    name="pump-1", address=1, control=True, nominal_frequency_hz=50.0, max_frequency_hz=50.0
)
FAN = DrivePlan(name="fan-1", address=2)
LINE = LinePlan(name="line1", port="sim://line1", drives=(PUMP, FAN))

Respond = Callable[[str, Command], CommandResult | Awaitable[CommandResult]]


def done(_drive: str, _command: Command) -> CommandResult:
    """Every command is carried out."""
    return CommandResult(outcome=Outcome.DONE)


class FakeGateway:
    """The daemon as an adapter sees it, built from a Hub, a FleetState and LineStats."""

    def __init__(self, lines: tuple[LinePlan, ...] = (LINE,), respond: Respond = done) -> None:
        self.plans = lines
        self.clock = MonotonicClock()
        self.hub = Hub()
        self.fleet = FleetState(lines, emit=self.hub.publish, clock=self.clock)
        self.stats = {line.name: LineStats(up_since=self.clock.now()) for line in lines}
        self.up = {line.name: True for line in lines}
        self.respond = respond
        self.executed: list[tuple[str, Command]] = []

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
            )
            for line in self.plans
        ]

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
                parameter=ParameterKey(param, 0), index=0, raw=raw, value=number, unit=unit
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


def http_model(**overrides: Any) -> HttpModel:
    """An ``http:`` section on an ephemeral loopback port with a viewer and an operator."""
    fields: dict[str, Any] = {
        "listen": "127.0.0.1:0",
        "tokens": [
            TokenModel(name="ops", role="operator", token=OPERATOR_TOKEN),
            TokenModel(name="scada", role="viewer", token=VIEWER_TOKEN),
        ],
    }
    fields.update(overrides)
    return HttpModel(**fields)


@asynccontextmanager
async def serving(
    gateway: FakeGateway, model: HttpModel | None = None, **options: Any
) -> AsyncIterator[HttpAdapter]:
    """The HTTP adapter over ``gateway``, listening until the block ends (bounded)."""
    async with asyncio.timeout(10):
        adapter = HttpAdapter(model or http_model(), gateway, **options)
        await adapter.__aenter__()
    try:
        yield adapter
    finally:
        async with asyncio.timeout(10):
            await adapter.__aexit__(None, None, None)


def free_port() -> int:
    """A TCP port nobody listens on right now (for configs the service binds itself)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def ws_url(adapter: HttpAdapter, query: str = "") -> str:
    """The stream's ws:// URL."""
    return adapter.url.replace("http://", "ws://") + "/api/v1/stream" + query


SERVICE_CONFIG = """
buses:
  - name: line1
    port: sim://line1
    baudrate: 115200
    drives:
      - {{name: pump-1, address: 1, control: bus, nominal_frequency_hz: 50, max_frequency_hz: 50}}
      - {{name: pump-2, address: 2, control: bus, nominal_frequency_hz: 50, max_frequency_hz: 60}}
      - {{name: fan-1, address: 3}}
  - name: line2
    port: sim://line2
    baudrate: 38400
    drives:
      - {{name: fan-2, address: 7}}
http:
  listen: 127.0.0.1:{port}
  tokens:
    - {{name: ops, role: operator, token: "{operator}"}}
    - {{name: scada, role: viewer, token: "{viewer}"}}
metrics: {{enabled: true}}
"""


def service_config(port: int) -> str:
    """Two simulated lines, four drives, and the HTTP adapter on ``port``."""
    return SERVICE_CONFIG.format(port=port, operator=OPERATOR_TOKEN, viewer=VIEWER_TOKEN)


async def wait_until_listening(url: str, timeout_s: float = 10.0) -> None:
    """Return once ``url`` answers HTTP (the service binds its adapter after the lines)."""
    async with asyncio.timeout(timeout_s), httpx.AsyncClient() as client:
        while True:
            try:
                await client.get(url + "/api/v1/openapi.json")
                return
            except httpx.TransportError:
                await asyncio.sleep(0.02)


class ServiceThread:
    """A real Service with simulated lines and the HTTP adapter, in a thread of its own.

    For callers that cannot share the test's event loop (schemathesis calls synchronously).
    """

    def __init__(self, text: str, port: int) -> None:
        self.url = f"http://127.0.0.1:{port}"
        self._text = text
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._failure: BaseException | None = None
        self._service: Service | None = None
        self._thread = threading.Thread(target=self._main, name="service", daemon=True)

    def _main(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._run())
        except BaseException as exc:  # reported to the test thread by start()
            self._failure = exc
            self._ready.set()
        finally:
            self._loop.close()

    async def _run(self) -> None:
        self._service = Service(config.parse(self._text))
        task = asyncio.create_task(self._service.run(install_signals=False))
        await wait_until_listening(self.url)
        self._ready.set()
        await task

    def start(self) -> None:
        self._thread.start()
        if not self._ready.wait(20) or self._failure is not None:
            raise RuntimeError(f"the service did not start: {self._failure!r}")

    def stop(self) -> None:
        if self._service is not None:
            self._loop.call_soon_threadsafe(self._service.stop)
        self._thread.join(20)
