"""DCMD: a host writes a drive's ``Control/*`` metrics, and each write is one command.

A write becomes the same command JSON every surface takes (DESIGN.md "Commands") and goes
the same way: :func:`~fcmaster.adapters.command_json.parse_command` against the drive's
plan (limits, magnitudes), then :meth:`Gateway.execute` (``control: bus``, the line's
confirmation, the audit). ``Control/Run`` true starts and false stops, ``Control/Reference
Hz`` sets the reference in Hz, ``Control/Reset`` true resets (false is no request). Whatever
ends before a line — commands switched off, a metric that is not writable, a value of the
wrong type, a reference beyond the drive's limits — ends here, audited, with its outcome.

The writes of one DCMD run in the order they came, in a task of their own, so a slow start
never holds up a stop for another drive. Every write gets exactly one outcome, handed to
``answer`` (the adapter publishes it as ``Control/Last Outcome`` and ``Control/Last Reason``).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

import structlog

from fcmaster.adapters.command_json import parse_command, refusal
from fcmaster.adapters.gateway import Gateway
from fcmaster.adapters.running import end_within
from fcmaster.adapters.sparkplug.metrics import CONTROL_METRICS, REFERENCE_HZ, RESET, RUN
from fcmaster.adapters.sparkplug.payload import Metric
from fcmaster.bus.audit import audit
from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.errors import UsageError

__all__ = ["DeviceCommands"]

log = structlog.get_logger("fcmaster.adapters.sparkplug")

Answer = Callable[[str, CommandResult], None]


def _payload(metric: Metric) -> dict[str, Any] | str | None:
    """The command JSON a written metric asks for; a reason when it asks for nothing valid."""
    value = metric.value
    if metric.name == RUN:
        if not isinstance(value, bool):
            return f"{RUN} takes a Boolean"
        return {"action": "start" if value else "stop"}
    if metric.name == REFERENCE_HZ:
        if isinstance(value, bool) or not isinstance(value, int | float):
            return f"{REFERENCE_HZ} takes a number"
        return {"action": "set_reference", "frequency_hz": value}
    if metric.name == RESET:
        if not isinstance(value, bool):
            return f"{RESET} takes a Boolean"
        return {"action": "reset"} if value else None
    writable = ", ".join(CONTROL_METRICS)
    return f"{metric.name!r} is not writable; these are: {writable}"


class DeviceCommands:
    """Turns DCMD metrics into commands and hands each outcome to ``answer``."""

    def __init__(self, gateway: Gateway, *, enabled: bool, actor: str, answer: Answer) -> None:
        self._gateway = gateway
        self.enabled = enabled
        self.actor = actor
        self._answer = answer
        self.running: set[asyncio.Task[None]] = set()

    def receive(self, device: str, metrics: tuple[Metric, ...] | None) -> None:
        """One DCMD for ``device`` (None: its payload could not be decoded); never blocks."""
        if metrics is None:
            self._refuse(device, None, Outcome.INVALID, "the DCMD payload is not Sparkplug B")
            return
        orders: list[Command] = []
        plan = self._gateway.drive_plan(device)
        for metric in metrics:
            asked = _payload(metric)
            if asked is None:
                continue
            action = asked.get("action") if isinstance(asked, dict) else None
            if isinstance(asked, str):
                self._refuse(device, action, Outcome.INVALID, asked)
            elif not self.enabled:
                reason = "commands over Sparkplug are off (sparkplug.commands: false)"
                self._refuse(device, action, Outcome.NOT_ALLOWED, reason, asked)
            elif plan is None:
                self._refuse(device, action, Outcome.INVALID, f"no drive {device!r}", asked)
            else:
                try:
                    orders.append(parse_command(asked, plan, actor=self.actor))
                except UsageError as exc:
                    result = refusal(exc)
                    self._refuse(device, action, result.outcome, result.reason, asked)
        if orders:
            task = asyncio.create_task(
                self._execute(device, orders), name=f"sparkplug.command[{device}]"
            )
            self.running.add(task)
            task.add_done_callback(self.running.discard)

    async def close(self, grace_s: float) -> None:
        """Give running commands ``grace_s`` to end; the rest end ``cancelled``."""
        await end_within(self.running, grace_s)

    async def _execute(self, device: str, orders: list[Command]) -> None:
        for at, command in enumerate(orders):
            try:
                result = await self._gateway.execute(device, command)
            except asyncio.CancelledError:
                reason = "the Sparkplug edge node stopped before the command ended"
                for _ in orders[at:]:
                    self._answer(device, CommandResult(outcome=Outcome.CANCELLED, reason=reason))
                raise
            except Exception as exc:  # one outcome, always, even when something below is broken
                log.exception("sparkplug.command_failed", drive=device, command=command.action)
                result = CommandResult(outcome=Outcome.CANCELLED, reason=f"internal error: {exc}")
            self._answer(device, result)

    def _refuse(
        self,
        device: str,
        action: object,
        outcome: Outcome,
        reason: str,
        values: dict[str, Any] | None = None,
    ) -> None:
        result = CommandResult(outcome=outcome, reason=reason)
        given = {k: v for k, v in (values or {}).items() if k != "action"}
        audit(log, actor=self.actor, drive=device, action=action, values=given, result=result)
        self._answer(device, result)
