"""The Modbus TCP adapter: every drive as a unit of registers, for PLCs and SCADA.

Theory of operation
-------------------
:class:`ModbusAdapter` is an async context manager the service enters once the lines are
up. Entering binds the listening socket (a taken port is a clear error naming
``modbus.listen``) and serves connections in the daemon's own event loop. Each connection
is one task that reads bytes, cuts them into requests (:mod:`.modbus_frames`) and answers
them one after the other, in the order they came: a PLC that pipelines a reference and a
start gets them carried out in that order. Connections never wait on each other.

Reads are answered from the fleet state in memory (:mod:`.modbus_map`), never with a bus
request. A write becomes a command for the shared command path — the same parser as HTTP
and MQTT, then ``gateway.execute`` with ``modbus:HOST:PORT`` as the actor — and is answered
only once that command has its one result: the normal answer when it is ``done``, else
the exception :data:`EXCEPTION_OF` maps its outcome to. Which command a write makes:

- ``command`` alone: that action; 0 does nothing;
- ``reference_hz`` alone: ``set_reference`` at that frequency;
- both in one write (FC 16 over registers 0-1): ``start`` carries the reference (one
  command, refused as a whole when the reference is beyond the drive's limits); with 0 only
  the reference is set; with any other action the action goes first and the reference
  follows once the action is done.

Safety rules (DESIGN.md "Safety and trust"): the listener is 127.0.0.1:5020 unless
``modbus.listen`` says otherwise, and listening beyond loopback needs ``modbus.allow``
(config validation refuses it otherwise); a connection from an address outside the allow
list (loopback only when there is none) is closed before a byte is read. Writes are
refused with ILLEGAL_FUNCTION unless ``modbus.commands: true``, and a refused write never
reaches a line. A header that is not Modbus TCP closes its connection; a frame begun is
given :data:`PARTIAL_FRAME_S` from its first byte to be completed (a byte now and then does
not keep it open), and a connection that sends nothing for :data:`IDLE_TIMEOUT_S` is closed.

No client locks the others out: when :data:`MAX_CONNECTIONS` are open, a new connection
takes the place of the one that has waited longest for its next request (the oldest idle
one), so silent connections cannot keep a PLC out. And no client flood slows the lines:
every request's answer is paced by one budget for the whole server (:class:`AnswerBudget`,
:data:`REQUESTS_PER_S`), so what the server costs the shared event loop is bounded per
second however many clients poll how fast; beyond it answers wait, their clients with them.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import socket
from collections import OrderedDict
from collections.abc import Sequence
from types import TracebackType
from typing import Any, Final

import structlog

from fcmaster.adapters.command_json import parse_command, refusal
from fcmaster.adapters.gateway import Gateway
from fcmaster.adapters.modbus_frames import (
    Broken,
    ExceptionCode,
    Function,
    MbapFramer,
    Refusal,
    Request,
    encode_exception,
    encode_registers,
    encode_written,
)
from fcmaster.adapters.modbus_map import (
    ACTIONS,
    COMMAND_ADDRESS,
    REFERENCE_ADDRESS,
    REFERENCE_DECIMALS,
    UnitMap,
    register_map,
)
from fcmaster.adapters.settings import ModbusSettings, modbus_listen
from fcmaster.adapters.tcp import no_delay
from fcmaster.bus.audit import audit, payload_values
from fcmaster.bus.commands import CommandResult, Outcome
from fcmaster.bus.plan import LinePlan
from fcmaster.errors import ConfigError, FcmasterError, UsageError

log = structlog.get_logger("fcmaster.adapters.modbus")

MAX_CONNECTIONS: Final = 64  # beyond this the oldest idle one makes room: bounded memory
PARTIAL_FRAME_S: Final = 5.0  # a frame begun must be whole by then (a stalled client)
IDLE_TIMEOUT_S: Final = 60.0  # a connection that sends nothing this long is closed
REQUESTS_PER_S: Final = 1000.0  # answers per second, all clients together (5 × 20 PLCs at 10 Hz)
REQUESTS_BURST: Final = 100  # answered at once after a quiet spell
SEND_TIMEOUT_S: Final = 10.0  # a client that stops reading its answers is dropped
READ_CHUNK: Final = 4096
SHUTDOWN_GRACE_S: Final = 2.0  # writes in progress may get their answer

# A command's outcome → the exception that answers its write (DESIGN.md "Modbus TCP").
# Keyed by the outcome's public name, so outcomes still to come are mapped already.
EXCEPTION_OF: Final = {
    "not_allowed": ExceptionCode.ILLEGAL_DATA_VALUE,
    "invalid": ExceptionCode.ILLEGAL_DATA_VALUE,
    "refused": ExceptionCode.SERVER_DEVICE_FAILURE,
    "unconfirmed": ExceptionCode.SERVER_DEVICE_FAILURE,
    "superseded": ExceptionCode.SERVER_DEVICE_FAILURE,
    "timeout": ExceptionCode.GATEWAY_TARGET_FAILED,
    "cancelled": ExceptionCode.GATEWAY_PATH_UNAVAILABLE,
}


class _Refused(FcmasterError):
    """A write answered with an exception before or instead of its command."""

    def __init__(self, code: ExceptionCode) -> None:
        self.code = code


class AnswerBudget:
    """Answers per second for the whole server (a generic cell rate: fair, first come)."""

    def __init__(self, per_s: float, burst: int) -> None:
        self.interval = 1.0 / per_s
        self.burst_s = (burst - 1) * self.interval  # so that exactly `burst` go at once
        self._due = 0.0  # when the budget is spent up to (the loop's time)
        self.waited = 0  # answers that had to wait for the budget

    def delay(self, now: float) -> float:
        """Take one answer's share: how long to wait before giving it (0: at once)."""
        due = max(self._due, now)
        self._due = due + self.interval
        wait = due - self.burst_s - now
        if wait <= 0:
            return 0.0
        self.waited += 1
        return wait


class ModbusAdapter:
    """Serves the register map while the context is entered.

    Built by the service as ``ModbusAdapter(settings, gateway, lines=…)``; ``lines`` give
    the drives and their monitored values, ``settings.units`` their unit ids.
    """

    def __init__(
        self,
        settings: ModbusSettings,
        gateway: Gateway,
        *,
        lines: Sequence[LinePlan],
        demo: bool = False,
        partial_frame_s: float = PARTIAL_FRAME_S,
        idle_timeout_s: float = IDLE_TIMEOUT_S,
        max_connections: int = MAX_CONNECTIONS,
        requests_per_s: float = REQUESTS_PER_S,
        shutdown_grace_s: float = SHUTDOWN_GRACE_S,
    ) -> None:
        self.settings = settings
        self.partial_frame_s = partial_frame_s
        self.idle_timeout_s = idle_timeout_s
        self.max_connections = max_connections
        self.budget = AnswerBudget(requests_per_s, REQUESTS_BURST)
        self.shutdown_grace_s = shutdown_grace_s
        self.gateway = gateway
        self.map = register_map(lines, settings.units)
        self._allow = tuple(ipaddress.ip_network(n, strict=False) for n in settings.allow or ())
        self._server: asyncio.Server | None = None
        self._connections: set[asyncio.Task[None]] = set()
        self._busy: set[asyncio.Task[None]] = set()  # answering a request right now
        # waiting for a request head with nothing begun, longest waiting first
        self._idle: OrderedDict[asyncio.Task[None], None] = OrderedDict()
        self.evicted = 0
        self._quiet = asyncio.Event()  # set while no request is being answered
        self._quiet.set()
        self._closing = False
        self._address: tuple[str, int] | None = None

    @property
    def address(self) -> tuple[str, int]:
        """The host and port it listens on (once entered)."""
        if self._address is None:
            raise RuntimeError("the Modbus adapter is not running")
        return self._address

    async def __aenter__(self) -> ModbusAdapter:
        if self._server is not None:
            raise RuntimeError("the Modbus adapter is already running")
        self._closing = False
        host, port = modbus_listen(self.settings.listen)
        assert port is not None  # the config checked it
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        try:
            sock = socket.create_server((host, port), family=family, backlog=128)
        except OSError as exc:
            reason = f"cannot listen on {self.settings.listen}: {exc.strerror or exc}"
            raise ConfigError([("modbus.listen", reason)]) from exc
        bound = sock.getsockname()
        self._address = (str(bound[0]), int(bound[1]))
        self._server = await asyncio.start_server(self._accept, sock=sock)
        log.info(
            "modbus.listening",
            host=self._address[0],
            port=self._address[1],
            units=len(self.map.units),
            commands=self.settings.commands,
            allow=self.settings.allow or ["loopback"],
        )
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        server, self._server = self._server, None
        if server is None:
            return
        server.close()
        # Idle connections end now; a write in progress may still get its answer (the
        # lines are still up: the service closes them after its adapters), and then its
        # connection ends. What is still going after the grace is cancelled and answered
        # GATEWAY_PATH_UNAVAILABLE.
        self._closing = True
        for task in self._connections - self._busy:
            task.cancel()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(self.shutdown_grace_s):
                await self._quiet.wait()
        for task in list(self._connections):
            task.cancel()
        if self._connections:
            await asyncio.wait(self._connections)
        await server.wait_closed()
        self._address = None
        log.info("modbus.stopped")

    # -- connections ---------------------------------------------------------------------

    def _allowed(self, host: str) -> bool:
        try:
            address = ipaddress.ip_address(host.partition("%")[0])
        except ValueError:
            return False
        if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
            address = address.ipv4_mapped
        if not self._allow:
            return address.is_loopback
        return any(address in network for network in self._allow)

    def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """A new connection: closed at once, or served by a task of its own.

        The task is ours rather than the server's, so the adapter can end it at shutdown.
        """
        no_delay(writer.transport)  # an answer goes out at once, not after the client's ACK
        peer = writer.get_extra_info("peername") or ("?", 0)
        host, port = str(peer[0]), int(peer[1])
        actor = f"modbus:[{host}]:{port}" if ":" in host else f"modbus:{host}:{port}"
        if not self._allowed(host) or (
            len(self._connections) >= self.max_connections and not self._idle
        ):
            why = "not in modbus.allow" if not self._allowed(host) else "too many connections"
            log.warning("modbus.client_refused", client=actor, reason=why)
            writer.close()
            return
        if len(self._connections) >= self.max_connections:  # the longest idle makes room
            oldest = next(iter(self._idle))
            del self._idle[oldest]
            self._connections.discard(oldest)
            oldest.cancel()
            self.evicted += 1
            log.info("modbus.client_evicted", client=oldest.get_name(), to_admit=actor)
        task = asyncio.create_task(
            self._connection(reader, writer, actor), name=f"modbus.client[{actor}]"
        )
        self._connections.add(task)
        task.add_done_callback(self._gone)

    def _gone(self, task: asyncio.Task[None]) -> None:
        self._connections.discard(task)
        self._idle.pop(task, None)

    async def _connection(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, actor: str
    ) -> None:
        log.info("modbus.client_connected", client=actor)
        try:
            await self._serve(reader, writer, actor)
        except (ConnectionError, TimeoutError) as exc:
            log.info("modbus.client_dropped", client=actor, reason=repr(exc))
        except Exception:  # a bug must cost this connection only, never the server
            log.exception("modbus.connection_failed", client=actor)
        finally:
            writer.close()
            log.info("modbus.client_disconnected", client=actor)

    async def _serve(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, actor: str
    ) -> None:
        framer = MbapFramer()
        task = asyncio.current_task()
        assert task is not None
        loop = asyncio.get_running_loop()
        begun: float | None = None  # when the frame being received began
        while True:
            item = framer.next_item()
            if item is None:
                if not framer.pending:
                    begun = None
                    self._idle[task] = None  # the newest idle one
                elif begun is None:
                    begun = loop.time()
                # A frame begun must be whole in time from its first byte, however its
                # bytes trickle in; between requests, a client has the idle timeout.
                deadline = (
                    loop.time() + self.idle_timeout_s
                    if begun is None
                    else begun + self.partial_frame_s
                )
                try:
                    async with asyncio.timeout_at(deadline):
                        data = await reader.read(READ_CHUNK)
                except TimeoutError:
                    why = (
                        f"sent nothing for {self.idle_timeout_s:g} s"
                        if begun is None
                        else (f"a frame not whole {self.partial_frame_s:g} s after its first byte")
                    )
                    log.info("modbus.client_dropped", client=actor, reason=why)
                    return
                finally:
                    self._idle.pop(task, None)
                if not data:
                    return
                framer.feed(data)
                continue
            begun = None
            if self._closing:
                return
            if isinstance(item, Broken):
                log.warning(
                    "modbus.frame_rejected", client=actor, reason=item.reason,
                    frame=item.data[:16].hex(" "),
                )  # fmt: skip
                return
            self._busy.add(task)
            self._quiet.clear()
            try:
                wait = self.budget.delay(loop.time())
                if wait:  # the server's answers per second are spent: this one waits
                    await asyncio.sleep(wait)
                answer = await self._answer(item, actor)
            except asyncio.CancelledError:  # shutdown: the request still gets its one answer
                code = ExceptionCode.GATEWAY_PATH_UNAVAILABLE
                writer.write(encode_exception(item.transaction, item.unit, item.function, code))
                raise
            finally:
                self._busy.discard(task)
                if not self._busy:
                    self._quiet.set()
            writer.write(answer)
            if self._closing:  # the answer goes out as the connection closes
                return
            async with asyncio.timeout(SEND_TIMEOUT_S):
                await writer.drain()

    # -- requests ------------------------------------------------------------------------

    async def _answer(self, item: Request | Refusal, actor: str) -> bytes:
        if isinstance(item, Refusal):
            log.debug("modbus.request_refused", client=actor, unit=item.unit, reason=item.reason)
            return encode_exception(item.transaction, item.unit, item.function, item.code)
        try:
            unit = self.map.units.get(item.unit)
            if unit is None:
                raise _Refused(ExceptionCode.GATEWAY_PATH_UNAVAILABLE)
            if item.function in (Function.READ_INPUT, Function.READ_HOLDING):
                return encode_registers(item, self._read(unit, item))
            await self._write(unit, item, actor)
            return encode_written(item)
        except _Refused as refused:
            return encode_exception(item.transaction, item.unit, item.function, refused.code)
        except Exception:  # a bug below must not take the server down: say so, keep serving
            log.exception("modbus.request_failed", client=actor, unit=item.unit)
            code = ExceptionCode.SERVER_DEVICE_FAILURE
            return encode_exception(item.transaction, item.unit, item.function, code)

    def _read(self, unit: UnitMap, request: Request) -> list[int]:
        table = "input" if request.function is Function.READ_INPUT else "holding"
        if request.address + request.count > unit.size(table):
            raise _Refused(ExceptionCode.ILLEGAL_DATA_ADDRESS)
        state = self.gateway.fleet.get(unit.bus, unit.drive.name)
        if state is None:
            raise _Refused(ExceptionCode.GATEWAY_PATH_UNAVAILABLE)
        words = unit.words(table, state, self.gateway.clock.wall())
        return words[request.address : request.address + request.count]

    async def _write(self, unit: UnitMap, request: Request, actor: str) -> None:
        drive = unit.drive.name
        if not self.settings.commands:
            self._refuse(actor, drive, "modbus.commands is false: the registers are read-only")
            raise _Refused(ExceptionCode.ILLEGAL_FUNCTION)
        if request.address + request.count > unit.size("holding"):
            self._refuse(actor, drive, f"no holding register {request.address + request.count - 1}")
            raise _Refused(ExceptionCode.ILLEGAL_DATA_ADDRESS)
        written = dict(enumerate(request.values, start=request.address))
        for payload in self._payloads(written, actor, drive):
            try:
                command = parse_command(payload, unit.drive, actor=actor)
            except UsageError as exc:
                self._refused_command(actor, drive, payload, refusal(exc))
                raise _Refused(ExceptionCode.ILLEGAL_DATA_VALUE) from None
            result: CommandResult = await self.gateway.execute(drive, command)
            if not result.ok:
                outcome = result.outcome.value
                raise _Refused(EXCEPTION_OF.get(outcome, ExceptionCode.SERVER_DEVICE_FAILURE))

    def _payloads(self, written: dict[int, int], actor: str, drive: str) -> list[dict[str, Any]]:
        """The commands a write of holding registers asks for (see the module docstring)."""
        code = written.get(COMMAND_ADDRESS)
        reference = written.get(REFERENCE_ADDRESS)
        set_reference = []
        frequency: dict[str, Any] = {}
        if reference is not None:
            frequency = {"frequency_hz": reference / 10**REFERENCE_DECIMALS}
            set_reference = [{"action": "set_reference", **frequency}]
        if code is None or code == 0:
            return set_reference
        action = ACTIONS.get(code)
        if action is None:
            known = ", ".join(f"{c} {a}" for c, a in ACTIONS.items())
            reason = f"command {code} is no action code ({known})"
            invalid = CommandResult(outcome=Outcome.INVALID, reason=reason)
            self._refused_command(actor, drive, {"value": code, **frequency}, invalid)
            raise _Refused(ExceptionCode.ILLEGAL_DATA_VALUE)
        if action == "start":
            return [{"action": "start", **frequency}]
        return [{"action": action}, *set_reference]

    @staticmethod
    def _refuse(actor: str, drive: str, reason: str) -> None:
        log.info("modbus.command_refused", actor=actor, drive=drive, reason=reason)

    def _refused_command(
        self, actor: str, drive: str, payload: dict[str, Any], result: CommandResult
    ) -> None:
        """A write refused as a command: logged, and audited with the values it carried."""
        self._refuse(actor, drive, result.reason)
        state = self.gateway.fleet.find(drive)
        audit(
            log,
            actor=actor,
            drive=drive,
            action=payload.get("action"),
            values=payload_values(payload),
            result=result,
            bus=None if state is None else state.bus,
        )
