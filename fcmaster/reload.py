"""What a reload changes: the running config and a new one compared, line by line.

Theory of operation
-------------------
A reload (SIGHUP) reads the config file again and judges it as ``fcmaster check`` does; a
file with any problem is refused whole and nothing changes. Otherwise :func:`compare` says
what to do, touching as little as it can, since every line it leaves alone keeps polling
without a missed poll and every adapter it leaves alone keeps its clients:

* a line whose port and settings (everything under its bus but its drives) are unchanged
  keeps its port open and takes its new drive list between two exchanges: drives added,
  removed or changed (a changed address, ``control`` or ``on_start`` makes it a new drive,
  taken over as at start; any other change keeps its state, so it is never jolted);
* a line whose port or settings changed is closed and opened again, alone; a line of a
  simulated port (``sim://``) also when its drives or its ``simulation`` changed, since its
  simulated drives are built with it;
* a line added is opened, a line removed is closed;
* an adapter whose section changed restarts alone (HTTP also for ``metrics``, MQTT also for
  ``http.tokens``, which its commands use, Modbus TCP also when the drives change, since its
  register map is theirs);
* ``on_shutdown`` takes effect at once; ``logging`` and ``journal`` at the next start.

A ``control: bus`` drive that leaves (removed, or its line removed) is left as
``on_shutdown`` says: with ``stop`` it is sent a stop first.
"""

from __future__ import annotations

import asyncio
import dataclasses
import hashlib
import socket
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Any, Protocol

import structlog

from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.bus.watchdog import WatchdogAudit
from fcmaster.clock import Clock
from fcmaster.config import Config
from fcmaster.drive_state import rfc3339
from fcmaster.errors import ConfigError
from fcmaster.journal import Journal
from fcmaster.offloop import run_off_loop
from fcmaster.state import FleetState

log = structlog.get_logger("fcmaster.reload")

ADAPTER_SECTIONS = ("http", "mqtt", "modbus", "opcua", "sparkplug")
STOP_TIMEOUT_S = 5.0  # for the stops of drives that leave (on_shutdown: stop)


@dataclass(slots=True)
class Changes:
    """What a new config changes, and how each change is applied."""

    described: list[str] = field(default_factory=list)  # in words, for the log and status
    open: list[LinePlan] = field(default_factory=list)  # lines added
    close: list[str] = field(default_factory=list)  # lines removed
    reopen: list[LinePlan] = field(default_factory=list)  # lines closed and opened again
    replan: list[LinePlan] = field(default_factory=list)  # lines that keep their port
    leaving: list[tuple[str, DrivePlan]] = field(default_factory=list)  # bus drives that go
    restart: list[str] = field(default_factory=list)  # adapter sections


def config_hash(config: Config) -> str:
    """A short fingerprint of what a config says (its validated content, not its layout)."""
    text = config.model.model_dump_json()
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _settings(line: LinePlan) -> LinePlan:
    return dataclasses.replace(line, drives=())


def _bus_model(config: Config, name: str) -> Any:
    return next(b for b in config.model.buses if b.name == name)


def _differs(old: Any, new: Any) -> list[str]:
    """The fields of two dataclasses or models that differ."""
    if dataclasses.is_dataclass(old):
        pairs = [
            (f.name, getattr(old, f.name), getattr(new, f.name)) for f in dataclasses.fields(old)
        ]
    else:
        pairs = [(name, getattr(old, name), getattr(new, name)) for name in type(old).model_fields]
    return [name for name, a, b in pairs if a != b]


def _drive_changes(bus: str, old: LinePlan, new: LinePlan, changes: Changes) -> bool:
    """Describe the drives ``new`` adds, removes and changes; whether there are any."""
    before = {d.name: d for d in old.drives}
    after = {d.name: d for d in new.drives}
    for name, drive in before.items():
        if name not in after:
            changes.described.append(f"{bus}: drive {name} removed")
            if drive.control:
                changes.leaving.append((bus, drive))
    for name, drive in after.items():
        was = before.get(name)
        if was is None:
            changes.described.append(f"{bus}: drive {name} added")
        elif was != drive:
            fields = ", ".join(_differs(was, drive))
            changes.described.append(f"{bus}: drive {name} changed ({fields})")
            if was.control and (was.address, was.on_start) != (drive.address, drive.on_start):
                changes.leaving.append((bus, was))  # taken over anew: the old one leaves
            elif was.control and not drive.control:
                changes.leaving.append((bus, was))
    return before != after or [d.name for d in old.drives] != [d.name for d in new.drives]


def compare(old: Config, new: Config) -> Changes:
    """What applying ``new`` over the running ``old`` takes."""
    changes = Changes()
    old_lines = {line.name: line for line in old.lines}
    new_lines = {line.name: line for line in new.lines}
    drives_changed = False
    for name, line in old_lines.items():
        if name not in new_lines:
            changes.close.append(name)
            changes.described.append(f"{name}: line removed")
            changes.leaving.extend((name, d) for d in line.drives if d.control)
            drives_changed = True
    for name, line in new_lines.items():
        was = old_lines.get(name)
        if was is None:
            changes.open.append(line)
            changes.described.append(f"{name}: line added")
            drives_changed = True
            continue
        settings = _differs(_settings(was), _settings(line))
        drives = _drive_changes(name, was, line, changes)
        drives_changed |= drives
        simulated = line.port.startswith("sim://")
        if simulated and _bus_model(old, name).simulation != _bus_model(new, name).simulation:
            settings.append("simulation")
        if settings or (simulated and drives):
            changes.reopen.append(line)
            reason = ", ".join(settings) or "its simulated drives"
            changes.described.append(f"{name}: line reopened ({reason} changed)")
        elif drives:
            changes.replan.append(line)
    for section in ADAPTER_SECTIONS:
        before, after = getattr(old.model, section), getattr(new.model, section)
        why = [] if before == after else ([section] if before is None or after is None else [
            f"{section}.{key}" for key in _differs(before, after)
        ])  # fmt: skip
        if section == "http" and old.model.metrics != new.model.metrics:
            why.append("metrics")
        if section in ("mqtt", "opcua") and after is not None and _tokens(old) != _tokens(new):
            why.append("http.tokens")
        if section in ("modbus", "opcua", "sparkplug") and after is not None and drives_changed:
            why.append("the drives")
        if why and (before is not None or after is not None):
            changes.restart.append(section)
            what = "stopped" if after is None else "started" if before is None else "restarted"
            changes.described.append(f"{section}: {what} ({', '.join(why)} changed)")
    if old.model.on_shutdown != new.model.on_shutdown:
        changes.described.append(f"on_shutdown: {new.model.on_shutdown}")
    for section in ("logging", "journal"):
        if getattr(old.model, section) != getattr(new.model, section):
            changes.described.append(f"{section}: changed, takes effect at the next start")
    return changes


def _tokens(config: Config) -> Any:
    return None if config.model.http is None else config.model.http.tokens


class Host(Protocol):
    """What the reload needs of the service."""

    config: Config
    fleet: FleetState
    masters: dict[str, BusMaster]
    journal: Journal

    @property
    def clock(self) -> Clock:
        """The service's clock."""

    def audit_of(self, bus: str) -> WatchdogAudit | None:
        """Line ``bus``'s watchdog audit."""

    async def execute(self, drive: str, command: Command) -> CommandResult:
        """Carry out ``command``; one result."""

    async def open_line(self, plan: LinePlan) -> None:
        """Start serving a line."""

    async def close_line(self, name: str) -> None:
        """Stop serving a line."""

    async def start_adapter(self, section: str) -> None:
        """Start a section's adapter."""

    async def stop_adapter(self, section: str) -> None:
        """Stop a section's adapter."""


class Reloader:
    """Reloads on request, one at a time, and keeps what the status and metrics show."""

    def __init__(self, host: Host, load: Callable[[Config], Config]) -> None:
        self._host = host
        self._load = load
        self.hash = config_hash(host.config)
        self.loaded_at = host.clock.wall()
        self.last: dict[str, Any] | None = None
        self.counts = {"applied": 0, "refused": 0}
        self._task: asyncio.Task[None] | None = None
        self._again = False
        self._ready = False  # until every line and adapter has started, requests wait
        self._asked = False

    def ready(self) -> None:
        """The service has started: a reload asked for meanwhile runs now."""
        self._ready = True
        if self._asked:
            self.request()

    def status(self) -> dict[str, Any]:
        """``config`` of ``GET /api/v1/status``."""
        return {
            "hash": self.hash,
            "loaded_at": rfc3339(self.loaded_at),
            "last_reload": self.last,
            "reloads": dict(self.counts),
        }

    def request(self) -> None:
        """Reload soon; a request during a reload makes one more after it."""
        if not self._ready:
            self._asked = True
            return
        if self._task is not None and not self._task.done():
            self._again = True
            return
        self._task = asyncio.create_task(self._run(), name="service.reload")

    async def aclose(self) -> None:
        """Shutdown: a reload under way is called off."""
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)

    async def _run(self) -> None:
        self._again = True
        while self._again:
            self._again = False
            try:
                await self.reload()
            except Exception as exc:  # a bug: said, and the daemon runs on
                log.error(
                    "config.reload_failed", error=f"{type(exc).__name__}: {exc}", exc_info=exc
                )

    async def reload(self) -> dict[str, Any]:
        """Read the config again; apply it or refuse it whole. The ``last_reload`` record."""
        host = self._host
        at = host.clock.wall()
        changes: list[str] = []
        running = host.config
        try:
            new, plan, fingerprint = await run_off_loop(partial(self._prepare, running))
            problems = _cannot_apply(running, new)
        except ConfigError as exc:
            problems = [f"{where}: {why}" for where, why in exc.problems]
        if problems:
            outcome = "refused"
            log.error("config.reload_refused", problems=problems)
        else:
            outcome = "applied"
            changes = plan.described
            problems = await self._apply(new, plan)
            self.hash = fingerprint
            self.loaded_at = at
            log.info("config.reloaded", changes=changes, problems=problems or None)
        self.counts[outcome] += 1
        self.last = {
            "at": rfc3339(at), "outcome": outcome, "changes": changes, "problems": problems,
        }  # fmt: skip
        host.journal.note("reload", outcome=outcome, changes=changes, problems=problems)
        return self.last

    def _prepare(self, running: Config) -> tuple[Config, Changes, str]:
        """The file read and judged, compared, fingerprinted (tens of ms: off the loop)."""
        new = self._load(running)
        return new, compare(running, new), config_hash(new)

    async def _apply(self, new: Config, changes: Changes) -> list[str]:
        """Apply ``changes``; what could not be done (the rest is done regardless)."""
        host = self._host
        problems: list[str] = []
        if changes.leaving and new.model.on_shutdown == "stop":
            problems += await self._stop(changes.leaving)
        old = {line.name: line for line in host.config.lines}
        for name in changes.close:
            await host.close_line(name)
            host.fleet.forget(name, {d.name for d in old[name].drives})
        host.config = new  # from here on, what the adapters and the lines are told
        for line in changes.reopen:
            await host.close_line(line.name)
            host.fleet.forget(line.name, _gone(old[line.name], line))
        for line in (*changes.reopen, *changes.open):
            host.fleet.replan(line)
            try:
                await host.open_line(line)
            except Exception as exc:  # e.g. its port in use by another program
                problems.append(f"{line.name}: not opened: {exc}")
                log.error("config.line_failed", bus=line.name, error=str(exc))
        for line in changes.replan:
            host.fleet.replan(line)  # before its first reply
            await host.masters[line.name].reconfigure(line)
            audit = host.audit_of(line.name)
            if audit is not None:
                audit.replan(line)
            host.fleet.forget(line.name, _gone(old[line.name], line))
        for section in changes.restart:
            await host.stop_adapter(section)
            try:
                await host.start_adapter(section)
            except Exception as exc:  # e.g. a port taken since it was checked
                problems.append(f"{section}: did not start: {exc}")
                log.error("config.adapter_failed", section=section, error=str(exc))
        return problems

    async def _stop(self, leaving: list[tuple[str, DrivePlan]]) -> list[str]:
        """Stop the ``control: bus`` drives that leave (on_shutdown: stop), bounded."""
        stop = Command(action=Action.STOP, actor="reload")
        orders = [self._host.execute(drive.name, stop) for _, drive in leaving]
        try:
            async with asyncio.timeout(STOP_TIMEOUT_S):
                results = await asyncio.gather(*orders)
        except TimeoutError:
            return ["stops of the drives that left: no outcome in time"]
        return [
            f"{bus}/{drive.name}: its stop ended {result.outcome.value} ({result.reason})"
            for (bus, drive), result in zip(leaving, results, strict=True)
            if result.outcome not in (Outcome.DONE, Outcome.UNCONFIRMED)
        ]


def _gone(old: LinePlan, new: LinePlan) -> set[str]:
    """Drives of ``old`` that ``new`` has not."""
    return {d.name for d in old.drives} - {d.name for d in new.drives}


def _cannot_apply(old: Config, new: Config) -> list[str]:
    """Problems ``check`` does not see: an HTTP address that cannot be had now."""
    listen = None if new.model.http is None else new.model.http.listen
    if listen is None or (old.model.http is not None and old.model.http.listen == listen):
        return []
    from fcmaster.adapters.http import parse_listen

    host, port = parse_listen(listen)
    try:
        socket.create_server(
            (host, port), family=socket.AF_INET6 if ":" in host else socket.AF_INET
        ).close()
    except OSError as exc:
        return [f"http.listen: cannot serve at {host}:{port}: {exc.strerror or exc}"]
    return []
