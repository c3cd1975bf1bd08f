"""The daemon: one BusMaster per line, the fleet state, the hub and the adapters.

Theory of operation
-------------------
:class:`Service` builds everything from a validated :class:`~fcmaster.config.Config`:
a :class:`~fcmaster.hub.Hub`, a :class:`~fcmaster.state.FleetState` that publishes to it,
and a BusMaster per line reporting to the fleet state. Each line owns its port and reopens
it by itself when it is lost, so one unplugged adapter never stops the other lines.
``sim://NAME`` ports get an in-process simulated line with the drives the config names.

Shutdown (SIGTERM, SIGINT, or :meth:`Service.stop`) is orderly. From that moment every
surface's new command ends ``cancelled`` ("fcmaster is shutting down") in :meth:`execute`,
and every queued command that is not a stop and not on the wire ends so too: the lines send
nothing but what ``on_shutdown`` asks for. With ``stop`` every ``control: bus`` drive is sent
a stop, which jumps every queue, and the service waits (bounded) for the results, and
names in an error each drive whose stop did not reach it (the line down, no answer); with
``hold`` the drives are left as they are and their own control-word timeout acts. Then the
service waits (bounded) until every command still running has its outcome, so that each
client gets its answer before the adapters close; then the lines close.

Under systemd with ``Type=notify`` (``$NOTIFY_SOCKET`` set), the service says ``READY=1``
once every line's port has been tried and every adapter is serving, and ``STOPPING=1``
when the shutdown begins; elsewhere it says nothing.
"""

from __future__ import annotations

import asyncio
import importlib
import os
import signal
import socket
from collections.abc import Callable
from contextlib import AbstractAsyncContextManager, AsyncExitStack
from typing import Any

import structlog

from fcmaster import health
from fcmaster.adapters.gateway import LineInfo
from fcmaster.bus.codecs import codec_for
from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.bus.echo import EchoCancellingTransport
from fcmaster.bus.frame_log import FramesSince
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.bus.serial import SerialTransport
from fcmaster.bus.transport import Transport
from fcmaster.bus.watchdog import WatchdogAudit
from fcmaster.clock import Clock, MonotonicClock
from fcmaster.config import Config
from fcmaster.hub import Hub
from fcmaster.state import FleetState

log = structlog.get_logger("fcmaster.service")

STATS_INTERVAL_S = 5.0
SHUTDOWN_STOP_TIMEOUT_S = 5.0
SHUTDOWN_COMMANDS_S = 5.0  # commands on the wire at shutdown: time to get their outcome
SHUTDOWN_ACTOR = "shutdown"
SHUTTING_DOWN = "fcmaster is shutting down"

TransportFactory = Callable[[LinePlan], Transport]

# config section → the adapter class it switches on, as "module:Class". Each adapter is an
# async context manager built as Class(section_settings, gateway, demo=bool).
ADAPTERS = {
    "http": "fcmaster.adapters.http:HttpAdapter",
    "mqtt": "fcmaster.adapters.mqtt:MqttAdapter",
    "modbus": "fcmaster.adapters.modbus:ModbusAdapter",
}


def notify_systemd(state: str) -> None:
    """Send ``state`` (``READY=1``, …) to systemd's ``$NOTIFY_SOCKET``, if there is one.

    The sd_notify protocol: one datagram on a Unix socket, a path or (``@``) an abstract
    name. Never blocks; a failure is logged, never raised.
    """
    address = os.environ.get("NOTIFY_SOCKET")
    if not address:
        return
    if address.startswith("@"):
        address = "\0" + address[1:]
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
            sock.setblocking(False)
            sock.sendto(state.encode(), address)
    except OSError as exc:
        log.warning("service.notify_failed", state=state, error=str(exc))


class Service:
    """Everything `fcmaster run` runs, for one configuration."""

    def __init__(
        self,
        config: Config,
        *,
        clock: Clock | None = None,
        transport_factory: TransportFactory | None = None,
        demo: bool = False,
    ) -> None:
        self.config = config
        self.demo = demo
        self.clock = clock or MonotonicClock()
        self.hub = Hub()
        self.fleet = FleetState(config.lines, emit=self.hub.publish, clock=self.clock)
        self._transport_factory = transport_factory or self._default_transport
        self.masters: dict[str, BusMaster] = {}
        self._audits: list[WatchdogAudit] = []  # one per line
        self._serial_ports: dict[str, SerialTransport] = {}  # by bus, for their adapters
        self._stopping = asyncio.Event()
        self._running_commands = 0
        self._no_commands = asyncio.Event()
        self._no_commands.set()

    def _default_transport(self, plan: LinePlan) -> Transport:
        if plan.port.startswith("sim://"):
            from fcmaster.sim.service import sim_transport

            bus = next(b for b in self.config.model.buses if b.name == plan.name)
            transport: Transport = sim_transport(plan, bus.simulation or {}, clock=self.clock)
        else:
            transport = SerialTransport(
                plan.port,
                baudrate=plan.baudrate,
                parity=plan.parity,
                stopbits=plan.stopbits,
                databits=plan.databits,
                rs485=plan.rs485,
                clock=self.clock,
            )
            self._serial_ports[plan.name] = transport
        return EchoCancellingTransport(transport) if plan.echo else transport

    def drive_plan(self, name: str) -> DrivePlan | None:
        """A drive's configuration, or None when no drive has that name."""
        for plan in self.config.lines:
            for drive in plan.drives:
                if drive.name == name:
                    return drive
        return None

    def lines(self) -> list[LineInfo]:
        """Every line with its statistics."""
        now = self.clock.now()
        infos = []
        for plan in self.config.lines:
            master = self.masters.get(plan.name)
            infos.append(
                LineInfo(
                    name=plan.name,
                    port=plan.port,
                    protocol=plan.protocol,
                    baudrate=plan.baudrate,
                    up=master is not None and master.is_up,
                    drives=tuple(d.name for d in plan.drives),
                    stats=master.stats.to_json(now) if master is not None else {},
                    adapter=_adapter_json(self._serial_ports.get(plan.name)),
                )
            )
        return infos

    def line_frames(self, name: str, since: int) -> tuple[LinePlan, FramesSince] | None:
        """Line ``name``'s plan and its recent frames from ``since`` on (None: no such line)."""
        master = self.masters.get(name)
        return None if master is None else (master.plan, master.frames.since(since))

    def master_of(self, drive: str) -> BusMaster:
        """The BusMaster of the line drive ``drive`` hangs on; KeyError if none."""
        state = self.fleet.find(drive)
        if state is None:
            raise KeyError(drive)
        return self.masters[state.bus]

    async def execute(self, drive: str, command: Command) -> CommandResult:
        """Carry out ``command`` on the drive called ``drive``, wherever it hangs."""
        try:
            master = self.master_of(drive)
        except KeyError:
            return CommandResult(outcome=Outcome.INVALID, reason=f"no drive called {drive!r}")
        if self._stopping.is_set():
            log.info(
                "command.completed",
                actor=command.actor or "-",
                bus=master.plan.name,
                drive=drive,
                command=command.action.value,
                outcome=Outcome.CANCELLED.value,
                reason=SHUTTING_DOWN,
            )
            return CommandResult(outcome=Outcome.CANCELLED, reason=SHUTTING_DOWN)
        self._running_commands += 1
        self._no_commands.clear()
        try:
            return await master.execute(drive, command)
        finally:
            self._running_commands -= 1
            if not self._running_commands:
                self._no_commands.set()

    def stop(self) -> None:
        """Ask :meth:`run` to shut down."""
        self._stopping.set()

    async def run(self, *, install_signals: bool = True) -> None:
        """Run until :meth:`stop` or SIGTERM/SIGINT; then shut down in order."""
        loop = asyncio.get_running_loop()
        if install_signals:
            for sig in (signal.SIGTERM, signal.SIGINT):
                loop.add_signal_handler(sig, self.stop)
        started = self.clock.now()  # what a restart costs each drive is counted from here
        health.watch_gc()  # its pauses stall every line's timers: /metrics shows them
        for section, target in ADAPTERS.items():
            if getattr(self.config, section) is not None:
                # Imported before the lines start: an import stalls the loop, and every line.
                importlib.import_module(target.partition(":")[0])
        try:
            async with AsyncExitStack() as stack:
                for plan in self.config.lines:
                    # Each commanded drive's own watchdog is read and judged when it comes
                    # online (fcmaster.bus.watchdog).
                    audit = WatchdogAudit(
                        plan, clock=self.clock, report=self.fleet.drive_watchdog, started_at=started
                    )
                    master = BusMaster(
                        plan,
                        codec=codec_for(plan),
                        transport=self._transport_factory(plan),
                        clock=self.clock,
                        observer=audit.observing(self.fleet),
                    )
                    audit.attach(master.execute, master.stats)
                    self._audits.append(audit)
                    self.masters[plan.name] = await stack.enter_async_context(master)
                    stack.push_async_callback(audit.aclose)  # before its line closes
                    serial = self._serial_ports.get(plan.name)
                    if serial is not None and serial.in_use is not None:
                        # Another fcmaster (or a tool) runs this line: a second master would
                        # only garble both. Unlike a missing adapter, this is not waited out.
                        raise serial.in_use
                for section, target in ADAPTERS.items():
                    settings = getattr(self.config, section)
                    if settings is not None:
                        await stack.enter_async_context(self._adapter(target, settings))
                # What start-up built lives as long as the daemon: out of the collector's way.
                frozen = health.freeze_start_up()
                log.info(
                    "service.started",
                    lines=len(self.masters),
                    drives=sum(len(p.drives) for p in self.config.lines),
                    gc_frozen=frozen,
                )
                notify_systemd("READY=1")
                stats = asyncio.create_task(self._publish_stats(), name="service.stats")
                try:
                    await self._stopping.wait()
                finally:
                    stats.cancel()
                log.info("service.stopping", on_shutdown=self.config.model.on_shutdown)
                notify_systemd("STOPPING=1")
                for audit in self._audits:
                    audit.stop()  # no more watchdog reads or writes: only what on_shutdown asks
                for master in self.masters.values():
                    master.cancel_queued(SHUTTING_DOWN)
                if self.config.model.on_shutdown == "stop":
                    await self._stop_drives()
                await self._commands_ended()
        finally:
            if install_signals:
                for sig in (signal.SIGTERM, signal.SIGINT):
                    loop.remove_signal_handler(sig)
            health.thaw()  # what was frozen may go now (a process that serves again)
        log.info("service.stopped")

    def _adapter(self, target: str, settings: Any) -> AbstractAsyncContextManager[Any]:
        module, _, name = target.partition(":")
        options: dict[str, Any] = {"demo": self.demo}
        if target == ADAPTERS["http"]:  # /metrics is served on the HTTP listener
            metrics = self.config.model.metrics
            options["metrics_enabled"] = metrics is not None and metrics.enabled
        if target == ADAPTERS["modbus"]:  # unit ids and monitored values come from the lines
            options["lines"] = self.config.lines
        if target == ADAPTERS["mqtt"]:  # MQTT commands carry the tokens of http.tokens
            http = self.config.http
            options["tokens"] = tuple(
                (t.name, t.role, t.secret) for t in (http.tokens if http else ())
            )
        factory = getattr(importlib.import_module(module), name)
        adapter: AbstractAsyncContextManager[Any] = factory(settings, self, **options)
        return adapter

    async def _stop_drives(self) -> None:
        """Send a stop to every bus-controlled drive and wait, bounded, for the results.

        A stop that ended without reaching its drive (the line down, no answer, a refusal)
        leaves a motor that may be turning: ``service.shutdown_stop_failed``, an error, per
        drive. One the drive took but whose status did not show it stopping in time
        (``unconfirmed``, or still being confirmed at the bound) is a warning.
        """
        orders = {
            (master.plan.name, drive.name): asyncio.ensure_future(
                master.execute(drive.name, Command(action=Action.STOP, actor=SHUTDOWN_ACTOR))
            )
            for master in self.masters.values()
            for drive in master.plan.drives
            if drive.control
        }
        if not orders:
            return
        # Bounded on the service's clock (virtual in tests), as the lines' own waits are.
        bound: asyncio.Future[None] = asyncio.ensure_future(
            self.clock.sleep(SHUTDOWN_STOP_TIMEOUT_S)
        )
        waiting: set[asyncio.Future[Any]] = set(orders.values())
        try:
            while waiting and not bound.done():
                _, waiting = await asyncio.wait(
                    {*waiting, bound}, return_when=asyncio.FIRST_COMPLETED
                )
                waiting.discard(bound)
        finally:
            bound.cancel()
            for order in orders.values():
                order.cancel()  # a no-op for those that have their result
        if waiting:
            late = [f"{bus}/{drive}" for (bus, drive), order in orders.items() if order in waiting]
            log.warning("service.shutdown_stop_timed_out", drives=late)
        for (bus, drive), order in orders.items():
            if order in waiting:
                continue
            result = order.result()
            if result.outcome is Outcome.UNCONFIRMED:
                log.warning(
                    "service.shutdown_stop_unconfirmed", bus=bus, drive=drive, reason=result.reason
                )
            elif result.outcome is not Outcome.DONE:
                log.error(
                    "service.shutdown_stop_failed",
                    bus=bus,
                    drive=drive,
                    outcome=result.outcome.value,
                    reason=result.reason,
                )

    async def _commands_ended(self) -> None:
        """Wait (bounded) until every command taken before the shutdown has its outcome."""
        try:
            async with asyncio.timeout(SHUTDOWN_COMMANDS_S):
                await self._no_commands.wait()
        except TimeoutError:
            log.warning("service.shutdown_commands_timed_out", running=self._running_commands)

    async def _publish_stats(self) -> None:
        while True:
            await self.clock.sleep(STATS_INTERVAL_S)
            now = self.clock.now()
            for name, master in self.masters.items():
                self.fleet.line_sampled(name, master.is_up, master.stats.to_json(now))


def _adapter_json(port: SerialTransport | None) -> dict[str, Any] | None:
    adapter = port.adapter if port is not None else None
    return adapter.to_json() if adapter is not None else None
