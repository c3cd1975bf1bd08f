"""Commands that come in over MQTT, each with exactly one result (DESIGN.md "Commands").

A command is checked where it arrives — JSON, an ``id``, a drive on the line its topic
names, and the shared parser — and whatever fails is answered ``invalid`` at once, so it
never reaches a line. A payload that is not a JSON object gets ``"id": null``. A valid
command runs in a task of its own: a slow read never holds up a stop for another drive.
Results go to the outbox, which keeps them across reconnects until the broker has them.
"""

from __future__ import annotations

import asyncio
import json
from dataclasses import dataclass
from typing import Any, Final

import aiomqtt
import structlog

from fcmaster.adapters.auth import Authenticator, AuthError, Role
from fcmaster.adapters.command_json import loads, parse_command, refusal
from fcmaster.adapters.gateway import Gateway
from fcmaster.adapters.mqtt_outbox import Outbox
from fcmaster.adapters.mqtt_topics import Topics, result_payload
from fcmaster.adapters.running import end_within
from fcmaster.bus.audit import audit, payload_values
from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.errors import UsageError

log = structlog.get_logger("fcmaster.adapters.mqtt")

MAX_COMMAND_BYTES = 64 * 1024


@dataclass(slots=True, frozen=True)
class CommandPolicy:
    """Whether commands are taken at all, and whose (``auth`` None: the broker decides)."""

    enabled: bool = False
    auth: Authenticator | None = None


TRUST_BROKER: Final = CommandPolicy(enabled=True)


class CommandDesk:
    """Takes command messages, runs the valid ones, and files one result for each."""

    def __init__(
        self,
        gateway: Gateway,
        topics: Topics,
        outbox: Outbox,
        *,
        actor: str,
        policy: CommandPolicy = TRUST_BROKER,
    ) -> None:
        """Commands for ``gateway``'s drives; results filed in ``outbox``.

        They are logged as ``actor``, unless ``policy`` asks for a token: its name is then
        the actor.
        """
        self._gateway = gateway
        self._topics = topics
        self._outbox = outbox
        self.actor = actor
        self._policy = policy
        self.running: set[asyncio.Task[None]] = set()

    def receive(self, message: aiomqtt.Message) -> None:
        """Handle one message from a command topic (never blocks)."""
        where = self._topics.parse_command(message.topic.value)
        if where is None:
            return
        bus, drive = where
        if message.retain:  # a stored command replayed on subscription: never run it again
            log.warning("mqtt.retained_command_ignored", bus=bus, drive=drive)
            return
        payload = message.payload
        try:
            if not isinstance(payload, bytes | bytearray):
                raise UsageError("the payload is not a JSON object")
            if len(payload) > MAX_COMMAND_BYTES:
                raise UsageError(f"the payload is longer than {MAX_COMMAND_BYTES} bytes")
            data = loads(payload)
        except UsageError as exc:
            self._invalid(bus, drive, None, None, str(exc))
            return
        except (ValueError, RecursionError) as exc:
            why = exc.msg if isinstance(exc, json.JSONDecodeError) and not exc.doc else exc
            self._invalid(bus, drive, None, None, f"the payload is not valid JSON: {why}")
            return
        self._command(bus, drive, data)

    async def close(self, grace_s: float) -> None:
        """Give running commands ``grace_s`` to end; the rest end ``cancelled``."""
        await end_within(self.running, grace_s)

    def _command(self, bus: str, drive: str, data: Any) -> None:
        if not isinstance(data, dict):
            self._invalid(bus, drive, None, None, 'a command is a JSON object like {"id": 1, …}')
            return
        command_id = data.get("id")
        raw_action = data.get("action")
        action = raw_action if isinstance(raw_action, str) else None
        given = payload_values(data)  # for the audit of a refusal
        if "id" not in data:
            reason = "'id' is missing: the result carries it"
            self._invalid(bus, drive, None, action, reason, given)
            return
        if isinstance(command_id, bool) or not isinstance(command_id, str | int):
            reason = "'id' must be a string or an integer"
            self._invalid(bus, drive, command_id, action, reason, given)
            return
        if not self._policy.enabled:
            reason = "commands over MQTT are off (mqtt.commands: false)"
            off = _result(Outcome.NOT_ALLOWED, reason)
            self._refused(bus, drive, command_id, action, off, given)
            return
        data = dict(data)
        secret = data.pop("token", None)
        actor = self.actor
        if self._policy.auth is not None or secret is not None:
            try:
                actor = self._operator(secret)
            except AuthError as exc:
                denied = _result(Outcome.NOT_ALLOWED, exc.reason)
                self._refused(bus, drive, command_id, action, denied, given)
                return
        plan = self._gateway.drive_plan(drive)
        if plan is None or self._gateway.fleet.get(bus, drive) is None:
            reason = f"no drive {drive!r} on bus {bus!r}"
            self._invalid(bus, drive, command_id, action, reason, given)
            return
        try:
            command = parse_command(data, plan, actor=actor)
        except UsageError as exc:
            self._refused(bus, drive, command_id, action, refusal(exc), given, actor=actor)
            return
        task = asyncio.create_task(
            self._execute(bus, drive, command_id, command), name=f"mqtt.command[{bus}/{drive}]"
        )
        self.running.add(task)
        task.add_done_callback(self.running.discard)

    def _operator(self, secret: Any) -> str:
        """The name of the operator token ``secret``; AuthError (never echoing it) if none."""
        auth = self._policy.auth or Authenticator((), anonymous=False)
        if not isinstance(secret, str) or not secret:
            raise AuthError(401, 'a command needs "token": an operator token of http.tokens')
        principal = auth.authenticate(f"Bearer {secret}", client_host=None, host_header=None)
        Authenticator.require(principal, Role.OPERATOR)
        return principal.name

    async def _execute(self, bus: str, drive: str, command_id: Any, command: Command) -> None:
        action = command.action.value
        try:
            result = await self._gateway.execute(drive, command)
        except asyncio.CancelledError:
            reason = "the MQTT bridge stopped before the command ended"
            self._answer(bus, drive, command_id, action, _result(Outcome.CANCELLED, reason))
            raise
        except Exception as exc:  # one result, always, even when something below is broken
            log.exception("mqtt.command_failed", bus=bus, drive=drive, command=action)
            result = _result(Outcome.CANCELLED, f"internal error: {exc}")
        self._answer(bus, drive, command_id, action, result)

    def _invalid(
        self,
        bus: str,
        drive: str,
        command_id: Any,
        action: str | None,
        reason: str,
        given: dict[str, object] | None = None,
    ) -> None:
        invalid = _result(Outcome.INVALID, reason)
        self._refused(bus, drive, command_id, action, invalid, given)

    def _refused(
        self,
        bus: str,
        drive: str,
        command_id: Any,
        action: str | None,
        result: CommandResult,
        given: dict[str, object] | None = None,
        *,
        actor: str | None = None,
    ) -> None:
        """A command that ends here, before a line: audited with the values it carried."""
        audit(
            log,
            actor=actor or self.actor,
            drive=drive,
            action=action,
            values=given or {},
            result=result,
            bus=bus,
            command_id=command_id,
        )
        self._answer(bus, drive, command_id, action, result)

    def _answer(
        self, bus: str, drive: str, command_id: Any, action: str | None, result: CommandResult
    ) -> None:
        payload = result_payload(command_id, bus, drive, action, result)
        self._outbox.result(self._topics.result(bus, drive), payload)


def _result(outcome: Outcome, reason: str) -> CommandResult:
    return CommandResult(outcome=outcome, reason=reason)
