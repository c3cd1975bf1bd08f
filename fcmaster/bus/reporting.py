"""A line's reporting: command results, drive and line events, counters, the observer.

The BusMaster decides; this tells. Each command that ends is audited once
(``command.completed``) and its callers' futures are resolved; line silence and drives
coming and going are logged; the per-drive counters are kept. What the layers above hear
(the :class:`~fcmaster.bus.observer.BusObserver`) is deferred until the next request is on
the wire, so the turnaround does not wait on it, and what an observer raises is logged
(``bus.observer_failed``) and goes no further.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from functools import partial
from typing import Any

from fcmaster.bus.audit import audit, command_values
from fcmaster.bus.commands import Action
from fcmaster.bus.observer import BusObserver
from fcmaster.bus.planner import Completion, Planner, Report, Step, StepKind
from fcmaster.bus.stats import LineStats
from fcmaster.clock import Clock
from fcmaster.protocol.codec import Reply


class LineReporter:
    """Tells the log, the callers and the observer what one line did."""

    def __init__(
        self,
        bus: str,
        *,
        planner: Planner,
        stats: LineStats,
        observer: BusObserver,
        clock: Clock,
        log: Any,
        recent_frames: Callable[[], list[str]],
    ) -> None:
        self._bus = bus
        self._planner = planner
        self._stats = stats
        self._observer = observer
        self._clock = clock
        self._log = log
        self._recent_frames = recent_frames
        self._deferred: list[Callable[[], None]] = []

    def notify(self, call: Callable[..., None], *args: object) -> None:
        """Tell the observer; what it raises is logged and goes no further than here."""
        try:
            call(*args)
        except Exception as exc:  # an observer's bug must not stop the line
            self._observer_failed(call, exc)

    def _observer_failed(self, call: Callable[..., None], exc: Exception) -> None:
        self._stats.observer_errors += 1
        name = getattr(call, "__name__", None) or getattr(
            getattr(call, "func", None), "__name__", "?"
        )
        self._log.error(
            "bus.observer_failed",
            call=name,
            error=f"{type(exc).__name__}: {exc}",
            exc_info=exc,
        )

    def handle(self, report: Report) -> None:
        """What the planner reports after a step: results, line silence, drives' comings."""
        if report.completions:
            self.resolve(report.completions)
        if report.line_silent is not None:
            self._stats.line_silent = report.line_silent
            if report.line_silent:
                self._log.warning("bus.line_silent", recent_frames=self._recent_frames())
            else:
                self._log.info("bus.line_answered")
        for transition in report.transitions:
            drive, online = transition.drive, transition.online
            now = self._clock.now()
            if online:
                self._log.info("drive.came_online", drive=drive.name, address=drive.address)
            else:
                self._log.warning(
                    "drive.went_offline",
                    drive=drive.name,
                    address=drive.address,
                    recent_frames=self._recent_frames(),
                )
            self._deferred.append(
                partial(self._observer.drive_availability, self._bus, drive, online, now)
            )

    def resolve(self, completions: list[Completion]) -> None:
        """End each command: audit it, answer its callers, tell the observer."""
        for completion in completions:
            result = completion.result
            command = completion.command
            if command.internal and command.action is Action.READ:
                for ticket in completion.tickets:  # housekeeping: no audit line, no event
                    if isinstance(ticket, asyncio.Future) and not ticket.done():
                        ticket.set_result(result)
                continue
            slot = self._planner.find(completion.drive)
            nominal = None if slot is None else slot.plan.nominal_frequency_hz
            audit(
                self._log,
                actor=command.actor,
                drive=completion.drive,
                action=command.action.value,
                values=command_values(command, nominal, result),
                result=result,
            )
            for ticket in completion.tickets:
                if isinstance(ticket, asyncio.Future) and not ticket.done():
                    ticket.set_result(result)
            self.notify(
                self._observer.command_completed, self._bus, completion.drive, command, result
            )

    def defer(self, call: Callable[[], None]) -> None:
        """Tell the observer later (:meth:`flush`): after the next request is written."""
        self._deferred.append(call)

    def flush(self) -> None:
        """Make the calls deferred: the layers above learn what the line did."""
        if self._deferred:
            deferred, self._deferred = self._deferred, []
            for call in deferred:
                try:
                    call()
                except Exception as exc:  # the same: isolated from the line
                    self._observer_failed(call, exc)

    def count_request(self, step: Step) -> None:
        """A request for ``step`` went out."""
        if step.pending is not None and step.pending.attempts:
            self._stats.retries += 1
        if step.slot is not None:
            drive = self._stats.drives[step.slot.plan.name]
            if not drive.requests:
                drive.first_request_at = self._clock.now()
            drive.requests += 1

    def count_reply(self, step: Step, reply: Reply, latency: float) -> None:
        """``step`` was answered."""
        if step.slot is not None:
            drive = self._stats.drives[step.slot.plan.name]
            drive.replies += 1
            drive.last_latency_s = latency
            if reply.error is not None:
                drive.refused += 1

    def count_failure(self, step: Step) -> None:
        """``step`` got no valid answer."""
        if step.slot is not None:
            self._stats.drives[step.slot.name].timeouts += 1
            if step.kind is StepKind.POLL:
                self._log.debug("poll.timed_out", address=step.slot.address)

    def timeout_reason(self, step: Step) -> str:
        """Why a command ended in a timeout, in words."""
        target = step.slot.name if step.slot else "the line"
        tries = 1 + (step.pending.attempts if step.pending else 0)
        return f"no valid reply from {target} after {tries} attempt(s)"
