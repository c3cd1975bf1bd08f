"""A BusMaster on a scripted FC line in virtual time, and what the tests ask of it."""

from __future__ import annotations

import asyncio
import dataclasses
import random
from collections.abc import Coroutine, Iterable
from dataclasses import dataclass, field
from typing import Any, TypeVar

from fcmaster.bus.commands import Command, CommandResult
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.protocol.codec import Reply
from fcmaster.protocol.danfoss_fc import ControlWord, Telegram, decode_telegram, encode_telegram
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.drive import ControlIntent
from tests.fakes import Responder, ScriptedTransport, Sent, Timed, VirtualClock
from tests.unit.bus.fcdrive import FcDrive, FcLine

T = TypeVar("T")

T0 = 1000.0
CHAR_S = 11 / 19200  # 8E1 at 19200 baud, the LinePlan default
PAUSE_S = 2 * CHAR_S  # the FC codec's minimum pause
DELAY_S = 0.010  # the scripted drives' response delay
PARAMETER = 16  # bytes of an FC parameter telegram
PROCESS = 8  # bytes of an FC process telegram

STOP_WORD = 0x043C
RUN_WORD = 0x047C
RESET_STOP_WORD = STOP_WORD | ControlWord.RESET
IGNORED = 0x0000


def exchange_s(request: int, reply: int) -> float:
    """Seconds from writing a request to the last byte of a prompt reply."""
    return (request + reply) * CHAR_S + DELAY_S


@dataclass
class Recorder:
    """A BusObserver that keeps everything it is told."""

    replies: list[tuple[str, Reply, float, ControlIntent | None]] = field(default_factory=list)
    availability: list[tuple[str, bool, float]] = field(default_factory=list)
    lines: list[tuple[bool, str, float]] = field(default_factory=list)
    results: list[tuple[str, Command, CommandResult]] = field(default_factory=list)
    replied_after_writes: list[int] = field(default_factory=list)
    transport: ScriptedTransport | None = None

    def drive_replied(
        self, bus: str, drive: DrivePlan, reply: Reply, at: float, commanded: ControlIntent | None
    ) -> None:
        self.replies.append((drive.name, reply, at, commanded))
        if self.transport is not None:
            self.replied_after_writes.append(len(self.transport.sent))

    def drive_availability(self, bus: str, drive: DrivePlan, online: bool, at: float) -> None:
        self.availability.append((drive.name, online, at))

    def line_availability(self, bus: str, up: bool, reason: str, at: float) -> None:
        self.lines.append((up, reason, at))

    def command_completed(
        self, bus: str, drive: str, command: Command, result: CommandResult
    ) -> None:
        self.results.append((drive, command, result))


@dataclass
class Bench:
    """One line: its drives, the scripted wire, the master and what it reported."""

    clock: VirtualClock
    transport: ScriptedTransport
    master: BusMaster
    observer: Recorder
    drives: dict[int, FcDrive]
    tasks: list[asyncio.Task[CommandResult]] = field(default_factory=list)

    @property
    def plan(self) -> LinePlan:
        return self.master.plan

    def requests(self, address: int | None = None) -> list[tuple[float, Telegram]]:
        """Every request written so far, decoded (only those to ``address`` if given)."""
        decoded = [(s.at, decode_telegram(s.data, from_drive=False)) for s in self.transport.sent]
        return [(at, t) for at, t in decoded if address is None or t.address == address]

    def words(self, address: int) -> list[int]:
        """The control words written to ``address``, in order."""
        return [t.pcd1 for _, t in self.requests(address)]

    def submit(self, command: Coroutine[Any, Any, CommandResult]) -> asyncio.Task[CommandResult]:
        """Start a command without waiting for it (as a second caller would)."""
        task = asyncio.ensure_future(command)
        self.tasks.append(task)
        return task

    async def complete(self, task: asyncio.Future[T], *, within: float = 10.0) -> T:
        return await self.clock.complete(task, within=within)

    async def mid_transaction(self) -> Sent:
        """Run until a request is on the wire and its reply not in yet; that request."""
        for _ in range(1000):
            last = self.transport.sent[-1] if self.transport.sent else None
            now = self.clock.now()
            if last is not None and last.reply_at is not None and last.at <= now < last.reply_at:
                return last
            await self.clock.run_for(0.001)
        raise AssertionError("no transaction in flight within 1 s")


def bench(
    *drives: DrivePlan,
    fc: Iterable[FcDrive] | None = None,
    responder: Responder | None = None,
    seed: int = 1,
    recorder: type[Recorder] = Recorder,
    answered_before: frozenset[int] = frozenset(),
    **options: Any,
) -> Bench:
    """A line named ``line1`` with ``drives``; each answered by an FcDrive unless ``fc`` says.

    ``answered_before``: the addresses the master is told answered when the daemon last ran.
    """
    plan = dataclasses.replace(LinePlan(name="line1", port="scripted", drives=drives), **options)
    clock = VirtualClock(T0)
    fc_drives = list(fc) if fc is not None else [FcDrive(d.address) for d in drives]
    transport = ScriptedTransport(clock, responder or FcLine(*fc_drives), delay_s=DELAY_S)
    observer = recorder(transport=transport)
    master = BusMaster(
        plan,
        codec=FcCodec(),
        transport=transport,
        clock=clock,
        observer=observer,
        rng=random.Random(seed),
        answered_before=answered_before,
    )
    return Bench(clock, transport, master, observer, {d.address: d for d in fc_drives})


def reply_frame(
    address: int, status: int = 0x0207, mav: int = 0, *, pke: int | None = None, pwe: int = 0
) -> bytes:
    """An FC reply frame, to script odd behaviour by hand."""
    return encode_telegram(Telegram(address=address, pcd1=status, pcd2=mav, pke=pke, pwe=pwe))


def delayed(responder: Responder, address: int, delay_s: float) -> Responder:
    """``responder``, but the drive at ``address`` answers ``delay_s`` after each request."""

    def respond(request: bytes) -> bytes | Timed | None:
        reply = responder(request)
        if isinstance(reply, bytes) and request[2] == 0x80 | address:
            return Timed(((delay_s, reply),))
        return reply

    return respond
