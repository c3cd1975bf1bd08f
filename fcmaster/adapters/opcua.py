"""The OPC UA adapter: the daemon's side of the OPC UA server, which runs as a child process.

Theory of operation
-------------------
OPC UA servers are heavy (asyncua: ~36 µs of CPU per change per subscriber, collections of
hundreds of milliseconds with 16,000 variables), and no client may make a line wait. So the
server runs in a process of its own (:mod:`fcmaster.opcua.server`), and this adapter only
feeds it over a Unix socket pair (:mod:`fcmaster.opcua.wire`), in the daemon's loop:

- one hub subscription, opened as the adapter starts, outlives the child: each batch takes
  what gathered (a drive's snapshots conflate in it, latest wins) and sends one ``drives``
  message with a compact entry per changed drive and a ``lines`` message for line changes;
  while the child is slow to read, the socket's buffer fills and the next batch waits,
  conflating meanwhile — never the bus;
- a ``call`` from the child is a command with actor ``opcua:<user>``: the user's role is
  looked up here in ``http.tokens`` (viewers, anonymous sessions and any call while
  ``opcua.commands`` is false are refused as ``not_allowed``, audited, and answered
  BadUserAccessDenied), then it goes through ``gateway.execute`` like every surface's
  commands, and its true outcome goes back as the call's ``Outcome`` and ``Reason``;
- if the child dies, it is started again after a backoff (1 s doubling to 30 s, reset once
  it ran a minute), with the whole fleet sent anew; the lines never notice. Calls it had
  in flight still end (their outcome is audited), and nobody waits for their answer.

The child is started in a session of its own, so a terminal's Ctrl-C reaches the daemon,
which decides; it ends by itself when its socket closes (the daemon stopped or died).
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any, Final

import structlog

from fcmaster.adapters.command_json import parse_command, refusal
from fcmaster.adapters.gateway import Gateway
from fcmaster.adapters.settings import OpcuaSettings, modbus_listen
from fcmaster.bus.audit import audit, payload_values
from fcmaster.bus.codecs import codec_for, monitor_keys
from fcmaster.bus.commands import CommandResult, Outcome
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.drive_state import DriveState, rfc3339
from fcmaster.errors import ConfigError, FcmasterError, UsageError
from fcmaster.hub import EventsDropped
from fcmaster.opcua.wire import Decoder, WireError, encode
from fcmaster.protocol.registry import spec_for
from fcmaster.state import DriveUpdated, LineChanged

log = structlog.get_logger("fcmaster.adapters.opcua")

BACKOFF_MIN_S: Final = 1.0
BACKOFF_MAX_S: Final = 30.0
STEADY_S: Final = 60.0  # a child that ran this long starts the backoff afresh
BATCH_S: Final = 0.05  # what gathered goes to the child at most this often
STOP_S: Final = 5.0  # the child's time to end once its socket is closed
# a line's counters as OPC UA shows them (stats key → variable)
COUNTERS: Final = {
    "requests": "Requests", "replies": "Replies", "timeouts": "Timeouts",
    "retries": "Retries", "checksum_errors": "ChecksumErrors", "reopens": "Reopens",
}  # fmt: skip


@dataclass(slots=True, frozen=True)
class CallResult:
    """What a method call ends with: the outcome, and whether the caller may not command."""

    outcome: str
    reason: str
    denied: bool = False  # answered BadUserAccessDenied rather than with an Outcome


def drive_entry(state: DriveState) -> dict[str, Any]:
    """A drive's compact form for the server: what its variables show, with reading times."""
    return {
        "name": state.name,
        "online": state.online,
        "at": state.updated_at,
        "running": state.running,
        "fault": state.fault,
        "warning": state.warning,
        "at_reference": state.at_reference,
        "direction": state.direction,
        "status_word": state.status_word,
        "ref": state.reference_pct,
        "alarms": [c.text for c in state.alarms],
        "warnings": [c.text for c in state.warnings],
        "wd": None if state.watchdog is None else state.watchdog.verdict,
        "f": state.output_frequency_hz,
        "f_at": state.output_frequency_updated_at,
        "values": {
            (m.name or parameter): [m.value, m.updated_at] for parameter, m in state.values.items()
        },
    }


def value_names(line: LinePlan, drive: DrivePlan) -> list[str]:
    """The names ``drive``'s monitored values go by in its state, before any was read.

    Each is the manual's name as a reading carries it, or the parameter where the tables
    name none (see :func:`drive_entry`), so the server shows every ``Values/`` variable from
    the start, waiting for its first reading, instead of one appearing when first read.
    """
    try:
        keys = monitor_keys(codec_for(line), drive)
        title_of = spec_for(line.protocol).parameters_of(line, drive.profile).title_of
    except FcmasterError:  # a plan the config would refuse: values appear as they come
        return []
    return list(dict.fromkeys(title_of(key) or key.name for key in keys))


def _session(given: Any) -> dict[str, Any]:
    """A session as the child listed it, with its ``since`` in RFC 3339."""
    since = given.get("since") if isinstance(given, dict) else None
    fields = ("user", "client", "application", "security")
    shown = {key: given.get(key) if isinstance(given, dict) else None for key in fields}
    return shown | {"since": rfc3339(since) if isinstance(since, int | float) else None}


def line_entry(name: str, up: bool, stats: dict[str, Any] | None) -> dict[str, Any]:
    """A line's compact form: up or not, and its counters."""
    given = stats or {}
    counters = {label: given[key] for key, label in COUNTERS.items() if key in given}
    return {"name": name, "up": up, "counters": counters}


class OpcuaAdapter:
    """Runs and feeds the OPC UA server process while the context is entered."""

    def __init__(
        self,
        settings: OpcuaSettings,
        gateway: Gateway,
        *,
        lines: Sequence[LinePlan],
        demo: bool = False,
        log_level: str = "info",
        backoff_min_s: float = BACKOFF_MIN_S,
    ) -> None:
        self.settings = settings
        self.gateway = gateway
        self.lines = tuple(lines)
        self.log_level = log_level
        self.backoff_min_s = backoff_min_s
        self._roles = {t.name: t.role for t in settings.users}
        self._task: asyncio.Task[None] | None = None
        self._calls: set[asyncio.Task[None]] = set()
        self.process: asyncio.subprocess.Process | None = None
        self.starts = 0
        self.ready = asyncio.Event()  # set while a child serves
        self.sessions: list[dict[str, Any]] = []  # the child's, as it last said

    async def __aenter__(self) -> OpcuaAdapter:
        if self._task is not None:
            raise RuntimeError("the OPC UA adapter is already running")
        self._check_listen()
        self._task = asyncio.create_task(self._supervise(), name="opcua.supervisor")
        return self

    def _check_listen(self) -> None:
        """A taken port is the user's to fix: said now, naming the key, not retried forever."""
        host, port = modbus_listen(self.settings.listen)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        try:
            socket.create_server((host, port or 0), family=family).close()
        except OSError as exc:
            reason = f"cannot listen on {self.settings.listen}: {exc.strerror or exc}"
            raise ConfigError([("opcua.listen", reason)]) from exc

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        task, self._task = self._task, None
        if task is None:
            return
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        for call in list(self._calls):
            call.cancel()  # its command still ends in the line, and is audited there
        log.info("opcua.stopped")

    # -- the child -----------------------------------------------------------------------

    async def _supervise(self) -> None:
        subscription = self.gateway.hub.subscribe(kinds=(DriveUpdated, LineChanged))
        backoff = self.backoff_min_s
        loop = asyncio.get_running_loop()
        try:
            while True:
                started = loop.time()
                code = await self._run_child(subscription)
                ran = loop.time() - started
                backoff = self.backoff_min_s if ran >= STEADY_S else backoff
                log.warning("opcua.server_exited", code=code, ran_s=round(ran, 1),
                            restart_in_s=backoff)  # fmt: skip
                await asyncio.sleep(backoff)
                backoff = min(BACKOFF_MAX_S, backoff * 2)
        finally:
            subscription.close()

    async def _run_child(self, subscription: Any) -> int | None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            process = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "fcmaster.opcua.server", "--fd", str(theirs.fileno()),
                pass_fds=(theirs.fileno(),), stdin=asyncio.subprocess.DEVNULL,
                stdout=asyncio.subprocess.DEVNULL, start_new_session=True,
            )  # fmt: skip
        finally:
            theirs.close()
        self.process = process
        self.starts += 1
        reader, writer = await asyncio.open_unix_connection(sock=ours)
        log.info("opcua.server_started", pid=process.pid, starts=self.starts)
        try:
            writer.write(encode(self.hello()))
            writer.write(encode({"t": "lines", "lines": self._lines_now()}))
            states = self.gateway.fleet.snapshot()
            writer.write(encode({"t": "drives", "drives": [drive_entry(s) for s in states]}))
            await writer.drain()
            async with asyncio.TaskGroup() as group:
                feed = group.create_task(self._feed(subscription, writer), name="opcua.feed")
                group.create_task(self._listen(reader, writer, feed), name="opcua.listen")
        except* (ConnectionError, WireError) as failed:
            log.warning("opcua.pipe_broken", reason=repr(failed.exceptions[0]))
        finally:
            self.ready.clear()
            self.sessions = []  # they ended with their server
            writer.close()
            try:
                async with asyncio.timeout(STOP_S):
                    await process.wait()
            except TimeoutError:
                process.kill()
                await process.wait()
            except asyncio.CancelledError:
                if process.returncode is None:
                    process.kill()
                    await process.wait()
                raise
        return process.returncode

    def status(self) -> dict[str, Any]:
        """The server as ``GET /api/v1/status`` shows it: where, whether up, its sessions."""
        return {
            "listen": self.settings.listen,
            "up": self.ready.is_set(),
            "restarts": max(0, self.starts - 1),
            "sessions": list(self.sessions),
        }

    def hello(self) -> dict[str, Any]:
        """The first message to a new server: its settings, users, drives and lines."""
        host, port = modbus_listen(self.settings.listen)
        drives = [
            {"name": d.name, "bus": line.name, "values": value_names(line, d)}
            for line in self.lines
            for d in line.drives
        ]
        lines = [{"name": line.name, "counters": list(COUNTERS.values())} for line in self.lines]
        settings = {
            "host": host, "port": port, "pki": self.settings.pki,
            "security": list(self.settings.security), "anonymous": self.settings.anonymous,
            "users": [[t.name, t.secret] for t in self.settings.users],
            "log_level": self.log_level,
        }  # fmt: skip
        return {"t": "hello", "settings": settings, "drives": drives, "lines": lines}

    def _lines_now(self) -> list[dict[str, Any]]:
        return [line_entry(i.name, i.up, i.stats) for i in self.gateway.lines()]

    async def _feed(self, subscription: Any, writer: asyncio.StreamWriter) -> None:
        """Send what the fleet does, a batch at a time (the subscription conflates between)."""
        while True:
            item = await subscription.get()
            drives: dict[str, dict[str, Any]] = {}
            lines: list[dict[str, Any]] = []
            while item is not None:
                if isinstance(item, DriveUpdated):
                    drives[item.state.key] = drive_entry(item.state)
                elif isinstance(item, LineChanged):
                    lines.append(line_entry(item.bus, item.up, item.stats))
                elif isinstance(item, EventsDropped):
                    lines = self._lines_now()  # line events were lost: send them all
                item = subscription.get_nowait()
            if lines:
                writer.write(encode({"t": "lines", "lines": lines}))
            if drives:
                writer.write(encode({"t": "drives", "drives": list(drives.values())}))
            await writer.drain()
            await asyncio.sleep(BATCH_S)

    async def _listen(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, feed: asyncio.Task[None]
    ) -> None:
        decoder = Decoder()
        while True:
            data = await reader.read(65536)
            if not data:
                feed.cancel()  # the child is gone
                return
            for message in decoder.feed(data):
                if message["t"] == "ready":
                    self.ready.set()
                    log.info("opcua.serving", listen=self.settings.listen)
                elif message["t"] == "sessions":
                    self.sessions = [_session(s) for s in message.get("sessions", ())]
                    log.info("opcua.sessions", users=[s["user"] for s in self.sessions])
                elif message["t"] == "call":
                    task = asyncio.create_task(self._call(message, writer), name="opcua.call")
                    self._calls.add(task)
                    task.add_done_callback(self._calls.discard)

    # -- calls ---------------------------------------------------------------------------

    async def _call(self, message: dict[str, Any], writer: asyncio.StreamWriter) -> None:
        user = message.get("user")
        drive = str(message.get("drive"))
        command = message.get("command")
        result = await self.execute_call(user, drive, command)
        if not writer.is_closing():
            answer = {"t": "result", "id": message.get("id"), "denied": result.denied}
            answer |= {"outcome": result.outcome, "reason": result.reason}
            writer.write(encode(answer))

    async def execute_call(self, user: str | None, drive: str, command: Any) -> CallResult:
        """A method call by ``user`` (None: anonymous) as a command, and how it ended."""
        actor = f"opcua:{user or 'anonymous'}"
        result, denied = await self._execute(actor, user, drive, command)
        return CallResult(result.outcome.value, result.reason, denied)

    async def _execute(
        self, actor: str, user: str | None, drive: str, command: Any
    ) -> tuple[CommandResult, bool]:
        reason = ""
        if not self.settings.commands:
            reason = "opcua.commands is false: the methods are not served"
        elif user is None or self._roles.get(user) != "operator":
            reason = f"{user or 'an anonymous session'} is no operator: only operators command"
        plan = self.gateway.drive_plan(drive)
        if not reason and plan is None:
            return CommandResult(outcome=Outcome.INVALID, reason=f"no drive {drive!r}"), False
        if reason or plan is None:
            result = CommandResult(outcome=Outcome.NOT_ALLOWED, reason=reason)
            self._audit_refusal(actor, drive, command, result)
            return result, True
        try:
            parsed = parse_command(command, plan, actor=actor)
        except UsageError as exc:
            result = refusal(exc)
            self._audit_refusal(actor, drive, command, result)
            return result, False
        return await self.gateway.execute(drive, parsed), False

    def _audit_refusal(self, actor: str, drive: str, command: Any, result: CommandResult) -> None:
        payload = command if isinstance(command, dict) else {}
        log.info("opcua.command_refused", actor=actor, drive=drive, reason=result.reason)
        state = self.gateway.fleet.find(drive)
        audit(log, actor=actor, drive=drive, action=payload.get("action"),
              values=payload_values(payload), result=result,
              bus=None if state is None else state.bus)  # fmt: skip
