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
service waits (bounded) until every command still running has its outcome. With ``stop`` the
bound follows the drives: a stop ends once the status shows the drive stopped, by a deadline
that follows its ramp (read from the drive, or its configured ``confirm_s``), so the service
waits for the slowest commanded drive's stop (at least 5 s), never longer than
``shutdown_timeout_s``; with ``hold`` it is 5 s. A daemon that exits mid-ramp is no danger
(the next start adopts the stop the drive executes), but a stop cut short has no outcome to
tell. Then the lines close, ending whatever is still open (a client's stop still waiting for
its ramp) while the adapters can still answer it, and the adapters close.

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

from fcmaster import config as config_module
from fcmaster import health
from fcmaster.adapters.gateway import LineInfo
from fcmaster.bus.audit import audit, command_values
from fcmaster.bus.codecs import codec_for
from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.bus.confirm import stop_known, stop_time
from fcmaster.bus.frame_log import FramesSince
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.bus.watchdog import WatchdogAudit
from fcmaster.clock import Clock, MonotonicClock
from fcmaster.config import Config
from fcmaster.errors import ConfigError
from fcmaster.hub import Hub
from fcmaster.journal import Journal
from fcmaster.presence import PresenceRecord, presence_path
from fcmaster.process_limits import RepeatedErrors, fit_file_limit
from fcmaster.reload import Reloader
from fcmaster.state import FleetState
from fcmaster.store_settings import StoreSettings
from fcmaster.transport.echo import EchoCancellingTransport
from fcmaster.transport.pipe import Transport
from fcmaster.transport.serial import SerialTransport

log = structlog.get_logger("fcmaster.service")

STATS_INTERVAL_S = 5.0
PRESENCE_S = 1.0  # how often the drives answering are noted (written only when they change)
JOURNAL_MEMORY_MB = 16.0  # a file without a journal section: kept in memory, this big at most
SHUTDOWN_STOP_TIMEOUT_S = 5.0  # the least a shutdown waits for stops and commands to end
SHUTDOWN_ACTOR = "shutdown"
SHUTTING_DOWN = "fcmaster is shutting down"

TransportFactory = Callable[[LinePlan], Transport]

# config section → the adapter class it switches on, as "module:Class". Each adapter is an
# async context manager built as Class(section_settings, gateway, demo=bool).
ADAPTERS = {
    "http": "fcmaster.adapters.http:HttpAdapter",
    "mqtt": "fcmaster.adapters.mqtt:MqttAdapter",
    "modbus": "fcmaster.adapters.modbus:ModbusAdapter",
    "opcua": "fcmaster.adapters.opcua:OpcuaAdapter",
    "sparkplug": "fcmaster.adapters.sparkplug.adapter:SparkplugAdapter",
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
        load: Callable[[Config], Config] | None = None,
    ) -> None:
        self.config = config
        self.demo = demo
        self.clock = clock or MonotonicClock()
        self.hub = Hub()
        self.fleet = FleetState(config.lines, emit=self.hub.publish, clock=self.clock)
        self.journal = Journal(
            config.journal or StoreSettings(max_mb=JOURNAL_MEMORY_MB),
            self.hub,
            wall=self.clock.wall,
        )
        # The drives answering when the daemon last ran: polled at once when their line opens.
        self.presence = PresenceRecord(presence_path(config.journal))
        self._transport_factory = transport_factory or self._default_transport
        self.masters: dict[str, BusMaster] = {}
        self._audits: list[WatchdogAudit] = []  # one per line
        self._serial_ports: dict[str, SerialTransport] = {}  # by bus, for their adapters
        # what runs, so that a reload can close and open each alone
        self._line_stacks: dict[str, AsyncExitStack] = {}
        self._adapter_stacks: dict[str, AsyncExitStack] = {}
        self._adapters: dict[str, Any] = {}  # each running adapter, by its config section
        self.reloader = Reloader(self, load or _load_again)
        self._stopping = asyncio.Event()
        self._running_commands = 0
        self._no_commands = asyncio.Event()
        self._no_commands.set()
        # "bus/drive" of each shutdown stop that ended without reaching its drive: the
        # motor may still turn, and `fcmaster run` says so with exit status 3
        self.stops_failed: list[str] = []

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
            result = CommandResult(outcome=Outcome.CANCELLED, reason=SHUTTING_DOWN)
            plan = self.drive_plan(drive)
            nominal = None if plan is None else plan.nominal_frequency_hz
            audit(
                log,
                actor=command.actor,
                drive=drive,
                action=command.action.value,
                values=command_values(command, nominal),
                result=result,
                bus=master.plan.name,
            )
            return result
        self._running_commands += 1
        self._no_commands.clear()
        try:
            return await master.execute(drive, command)
        finally:
            self._running_commands -= 1
            if not self._running_commands:
                self._no_commands.set()

    async def events(
        self,
        *,
        since: float | None = None,
        kind: str | None = None,
        drive: str | None = None,
        limit: int = 100,
    ) -> list[dict[str, Any]]:
        """The journal's newest ``limit`` records matching the filters, oldest first."""
        return await self.journal.read(since=since, kind=kind, drive=drive, limit=limit)

    def stop(self) -> None:
        """Ask :meth:`run` to shut down."""
        self._stopping.set()

    def request_reload(self) -> None:
        """SIGHUP: read the config file again and apply what changed (see fcmaster.reload)."""
        log.info("config.reload_requested", path=str(self.config.path))
        self.reloader.request()

    def audit_of(self, bus: str) -> WatchdogAudit | None:
        """Line ``bus``'s watchdog audit (None: no such line)."""
        return next((audit for audit in self._audits if audit.plan.name == bus), None)

    def config_status(self) -> dict[str, Any]:
        """The running config: its hash, when it was loaded, and how the last reload went."""
        return self.reloader.status()

    def opcua_status(self) -> dict[str, Any] | None:
        """The OPC UA server's state and sessions (None: no ``opcua:`` section)."""
        adapter = self._adapters.get("opcua")
        status: dict[str, Any] | None = None if adapter is None else adapter.status()
        return status

    async def run(self, *, install_signals: bool = True) -> None:
        """Run until :meth:`stop` or SIGTERM/SIGINT; then shut down in order."""
        loop = asyncio.get_running_loop()
        if install_signals:  # the process is ours: its signals, its files, its loop's errors
            for sig in (signal.SIGTERM, signal.SIGINT):
                loop.add_signal_handler(sig, self.stop)
            # SIGHUP's default action ends the process on the spot (no on_shutdown, and
            # systemd counts it a clean exit): here it asks for a reload.
            loop.add_signal_handler(signal.SIGHUP, self.request_reload)
            fit_file_limit()
            RepeatedErrors(loop).install()
        self._started_at = self.clock.now()  # what a restart costs each drive counts from here
        health.watch_gc()  # its pauses stall every line's timers: /metrics shows them
        for section, target in ADAPTERS.items():
            if getattr(self.config, section) is not None:
                # Imported before the lines start: an import stalls the loop, and every line.
                importlib.import_module(target.partition(":")[0])
        try:
            async with AsyncExitStack() as stack:
                # First in, last out: it sees the lines open and every command end.
                await stack.enter_async_context(self.journal)
                stack.push_async_callback(self._close_lines)
                for plan in self.config.lines:
                    await self.open_line(plan, at_start=True)
                stack.push_async_callback(self._stop_adapters)
                for section in ADAPTERS:
                    await self.start_adapter(section)
                # What start-up built lives as long as the daemon: out of the collector's way.
                frozen = health.freeze_start_up()
                lines, drives = len(self.masters), sum(len(p.drives) for p in self.config.lines)
                log.info("service.started", lines=lines, drives=drives, gc_frozen=frozen)
                self.journal.note("start", lines=lines, drives=drives)
                notify_systemd("READY=1")
                self.reloader.ready()
                stats = asyncio.create_task(self._publish_stats(), name="service.stats")
                presence = asyncio.create_task(self._keep_presence(), name="service.presence")
                try:
                    await self._stopping.wait()
                finally:
                    stats.cancel()
                    presence.cancel()
                    await self.reloader.aclose()
                await self._note_presence()  # before the shutdown closes the ports
                log.info("service.stopping", on_shutdown=self.config.model.on_shutdown)
                self.journal.note("stop", on_shutdown=self.config.model.on_shutdown)
                notify_systemd("STOPPING=1")
                for audit in self._audits:
                    audit.stop()  # no more watchdog reads or writes: only what on_shutdown asks
                deadline = self.clock.now() + self._shutdown_bound_s()
                for master in self.masters.values():
                    master.cancel_queued(SHUTTING_DOWN)
                if self.config.model.on_shutdown == "stop":
                    await self._stop_drives(deadline)
                await self._commands_ended(deadline)
                for master in self.masters.values():
                    # What is still open ends now, while the adapters (closing first on the
                    # way out) can still answer its client.
                    await master.close()
        finally:
            if install_signals:
                for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
                    loop.remove_signal_handler(sig)
            health.thaw()  # what was frozen may go now (a process that serves again)
        log.info("service.stopped")

    async def open_line(self, plan: LinePlan, *, at_start: bool = False) -> None:
        """Start serving line ``plan`` (at start, or a line a reload adds or reopens).

        The watchdog audit counts what taking the drives over cost them from the daemon's
        start (``at_start``), or from now: a line a reload opens was not fed by anyone before.
        """
        stack = AsyncExitStack()
        self._line_stacks[plan.name] = stack
        # Each commanded drive's own watchdog is read and judged when it comes online
        # (fcmaster.bus.watchdog).
        audit = WatchdogAudit(
            plan,
            clock=self.clock,
            report=self.fleet.drive_watchdog,
            started_at=self._started_at if at_start else None,
        )
        master = BusMaster(
            plan,
            codec=codec_for(plan),
            transport=self._transport_factory(plan),
            clock=self.clock,
            observer=audit.observing(self.fleet),
            answered_before=self.presence.answered_before(plan),
        )
        audit.attach(master.execute, master.stats)
        self._audits.append(audit)
        stack.callback(self._audits.remove, audit)
        try:
            self.masters[plan.name] = await stack.enter_async_context(master)
            stack.callback(self.masters.pop, plan.name)
            stack.push_async_callback(audit.aclose)  # before its line closes
            serial = self._serial_ports.get(plan.name)
            if serial is not None and serial.in_use is not None:
                # Another fcmaster (or a tool) runs this line: a second master would only
                # garble both. Unlike a missing adapter, this is not waited out.
                raise serial.in_use
        except BaseException:
            await self.close_line(plan.name)
            raise

    async def close_line(self, name: str) -> None:
        """Stop serving line ``name`` (a reload removes or reopens it)."""
        stack = self._line_stacks.pop(name, None)
        if stack is not None:
            await stack.aclose()
        self._serial_ports.pop(name, None)

    async def _close_lines(self) -> None:
        for name in reversed(list(self._line_stacks)):
            await self.close_line(name)

    async def start_adapter(self, section: str) -> None:
        """Start the adapter of config section ``section``, if the config has it."""
        settings = getattr(self.config, section)
        if settings is not None:
            stack = AsyncExitStack()
            adapter = await stack.enter_async_context(self._adapter(ADAPTERS[section], settings))
            self._adapter_stacks[section] = stack
            self._adapters[section] = adapter

    async def stop_adapter(self, section: str) -> None:
        """Stop the adapter of config section ``section``, if it runs."""
        stack = self._adapter_stacks.pop(section, None)
        self._adapters.pop(section, None)
        if stack is not None:
            await stack.aclose()

    async def _stop_adapters(self) -> None:
        for section in reversed(list(self._adapter_stacks)):
            await self.stop_adapter(section)

    def _adapter(self, target: str, settings: Any) -> AbstractAsyncContextManager[Any]:
        module, _, name = target.partition(":")
        options: dict[str, Any] = {"demo": self.demo}
        if target == ADAPTERS["http"]:  # /metrics is served on the HTTP listener
            metrics = self.config.model.metrics
            options["metrics_enabled"] = metrics is not None and metrics.enabled
        if target in (ADAPTERS["modbus"], ADAPTERS["opcua"]):  # their drives are the lines'
            options["lines"] = self.config.lines
        if target == ADAPTERS["opcua"]:  # the server process logs as the daemon does
            options["log_level"] = self.config.model.logging.level
        if target == ADAPTERS["mqtt"]:  # MQTT commands carry the tokens of http.tokens
            http = self.config.http
            options["tokens"] = tuple(
                (t.name, t.role, t.secret) for t in (http.tokens if http else ())
            )
        factory = getattr(importlib.import_module(module), name)
        adapter: AbstractAsyncContextManager[Any] = factory(settings, self, **options)
        return adapter

    def _shutdown_bound_s(self) -> float:
        """How long the shutdown may wait: the slowest commanded drive's stop, within the cap.

        A stop's own deadline already has a grace beyond the ramp (confirm.RAMP_GRACE_S), so a
        drive that stops within its ramp shows it before this bound. With ``hold`` the drives
        are left as they are: a client's command still running gets the least bound.
        """
        if self.config.model.on_shutdown != "stop":
            return min(self.config.model.shutdown_timeout_s, SHUTDOWN_STOP_TIMEOUT_S)
        slowest = [
            stop_time(slot)
            for master in self.masters.values()
            for slot in master.planner.slots
            if slot.plan.control and stop_known(slot)
        ]
        cap = self.config.model.shutdown_timeout_s
        return min(cap, max([SHUTDOWN_STOP_TIMEOUT_S, *slowest]))

    async def _stop_drives(self, deadline: float) -> None:
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
            self.clock.sleep(max(0.0, deadline - self.clock.now()))
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
                self.stops_failed.append(f"{bus}/{drive}")
                log.error(
                    "service.shutdown_stop_failed",
                    bus=bus,
                    drive=drive,
                    outcome=result.outcome.value,
                    reason=result.reason,
                )

    async def _commands_ended(self, deadline: float) -> None:
        """Wait, until ``deadline``, for every command taken before the shutdown to end."""
        ended = asyncio.ensure_future(self._no_commands.wait())
        bound = asyncio.ensure_future(self.clock.sleep(max(0.0, deadline - self.clock.now())))
        try:
            await asyncio.wait((ended, bound), return_when=asyncio.FIRST_COMPLETED)
        finally:
            bound.cancel()
            ended.cancel()
        if not self._no_commands.is_set():
            log.warning("service.shutdown_commands_timed_out", running=self._running_commands)

    async def _keep_presence(self) -> None:
        while True:
            await self.clock.sleep(PRESENCE_S)
            await self._note_presence()

    async def _note_presence(self) -> None:
        for name, master in self.masters.items():
            hearing = master.is_up and not master.planner.line_silent
            self.presence.update(name, hearing, master.planner.slots)
        await self.presence.save()

    async def _publish_stats(self) -> None:
        while True:
            await self.clock.sleep(STATS_INTERVAL_S)
            now = self.clock.now()
            for name, master in self.masters.items():
                self.fleet.line_sampled(name, master.is_up, master.stats.to_json(now))


def _adapter_json(port: SerialTransport | None) -> dict[str, Any] | None:
    adapter = port.adapter if port is not None else None
    return adapter.to_json() if adapter is not None else None


def _load_again(running: Config) -> Config:
    """The running config's file read and judged again (ConfigError: refused)."""
    if running.path is None:
        raise ConfigError([("(file)", "this config was not read from a file")])
    return config_module.load(running.path)
