"""How the HTTP API reads a request: strict JSON bodies, the caller, and refusals logged.

Command bodies follow the rules of :mod:`fcmaster.adapters.command_json` (no duplicated
key, no NaN) because every route reads its body through :class:`StrictJsonRoute`. The
caller is the :class:`~fcmaster.adapters.auth.Principal` its bearer token names
(:data:`Viewer`, :data:`Operator` as route dependencies). A request refused before it
reaches a line is logged as ``http.command_refused`` by :func:`log_refused`; one refused as
a command (malformed, beyond the drive's limits, no such drive) is also audited as every
ended command is, with its values (:func:`refused_command`). One refused for its caller (no
token, a viewer's) is no one's command: only the first.
"""

from __future__ import annotations

from typing import Annotated, Any

import structlog
from fastapi import Depends, Request, Security
from fastapi.exceptions import RequestValidationError
from fastapi.responses import Response
from fastapi.routing import APIRoute
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.exceptions import HTTPException
from starlette.requests import ClientDisconnect
from starlette.types import Scope

from fcmaster.adapters.auth import Authenticator, AuthError, Principal, Role
from fcmaster.adapters.command_json import loads
from fcmaster.adapters.middleware import replaying
from fcmaster.bus.audit import audit, payload_values
from fcmaster.bus.commands import CommandResult

log = structlog.get_logger("fcmaster.adapters.http")

_bearer = HTTPBearer(auto_error=False, description="a token from http.tokens")


def describe_error(error: dict[str, Any]) -> str:
    """One validation error of FastAPI's, in words: where, and what is wrong there."""
    where = ".".join(str(part) for part in error.get("loc", ()))
    if error.get("type") == "json_invalid":
        return f"the body is not valid JSON: {error.get('ctx', {}).get('error', 'unreadable')}"
    return f"{where}: {error.get('msg', 'invalid')}"


async def peek_payload(request: Request) -> object:
    """A request's body as JSON, if it can be read at all (for the log); None if not."""
    try:
        return loads(await request.body())
    except (ValueError, ClientDisconnect, HTTPException):  # not JSON, gone, or too large
        return None


async def peek_action(request: Request) -> str | None:
    """The ``action`` a request's body names, if it can be read at all (for the log)."""
    return _action(await peek_payload(request))


def _action(payload: object) -> str | None:
    action = payload.get("action") if isinstance(payload, dict) else None
    return action if isinstance(action, str) else None


class _StrictJsonRequest(Request):
    """A request whose JSON body follows the command rules (no duplicated keys, no NaN)."""

    async def json(self) -> Any:
        """The body as JSON; json.JSONDecodeError (a 422 ``invalid``) when it breaks a rule."""
        if not hasattr(self, "_json"):
            self._json = loads(await self.body())
        return self._json


# What `curl -d` sends (form), what a hand-written request may say (text/plain), or nothing:
# every body this API takes is JSON, so these are read as JSON. Bearer tokens keep that safe
# from other sites' forms, which cannot send an Authorization header.
_TAKEN_AS_JSON = frozenset({"", "application/x-www-form-urlencoded", "text/plain"})


def as_json(scope: Scope, body: bytes) -> Scope:
    """``scope`` with a body sent without ``Content-Type: application/json`` marked as JSON.

    RequestValidationError, naming the header, for a body of another type (XML, multipart…).
    """
    if not body:
        return scope
    headers = [(k, v) for k, v in scope["headers"] if k != b"content-type"]
    declared = dict(scope["headers"]).get(b"content-type", b"").decode("latin-1")
    kind = declared.split(";")[0].strip().lower()
    if kind == "application/json" or kind.endswith("+json"):
        return scope
    if kind not in _TAKEN_AS_JSON:
        reason = f"the body must be JSON, sent with Content-Type: application/json, not {kind}"
        raise RequestValidationError(
            [{"type": "content_type", "loc": ("header", "content-type"), "msg": reason}]
        )
    return {**scope, "headers": [*headers, (b"content-type", b"application/json")]}


class StrictJsonRoute(APIRoute):
    """Routes that read bodies by the command rules (a strict request)."""

    def get_route_handler(self) -> Any:
        """FastAPI's handler, handed the strict request."""
        handler = super().get_route_handler()

        async def strict(request: Request) -> Response:
            # Read through ``request``, which caches the body for the error handlers.
            body = await request.body()
            response: Response = await handler(
                _StrictJsonRequest(as_json(request.scope, body), replaying(body, request.receive))
            )
            return response

        return strict


def _caller(
    request: Request,
    _: Annotated[HTTPAuthorizationCredentials | None, Security(_bearer)],
) -> Principal:
    auth: Authenticator = request.app.state.auth
    return auth.authenticate(
        request.headers.get("authorization"),
        client_host=request.client.host if request.client else None,
        host_header=request.headers.get("host"),
    )


def _operator(principal: Annotated[Principal, Depends(_caller)]) -> Principal:
    Authenticator.require(principal, Role.OPERATOR)
    return principal


Viewer = Annotated[Principal, Depends(_caller)]
Operator = Annotated[Principal, Depends(_operator)]


def actor_of(auth: Authenticator, request: Request) -> str:
    """The name of the request's caller for the log; "-" when it is not let in."""
    try:
        return auth.authenticate(
            request.headers.get("authorization"),
            client_host=request.client.host if request.client else None,
            host_header=request.headers.get("host"),
        ).name
    except AuthError:
        return "-"


def log_refused(actor: str, drive: object, action: object, outcome: str, reason: str) -> None:
    """Log a command refused before it reached a line (``http.command_refused``)."""
    log.info(
        "http.command_refused",
        actor=actor or "-",
        drive=drive,
        command=action if isinstance(action, str) else None,
        outcome=outcome,
        reason=reason,
    )


def refused_command(
    actor: str, drive: str, payload: object, result: CommandResult, bus: str | None
) -> None:
    """A command that ended before it reached a line: logged, and audited with its values."""
    action = _action(payload)
    log_refused(actor, drive, action, result.outcome.value, result.reason)
    audit(
        log,
        actor=actor,
        drive=drive,
        action=action,
        values=payload_values(payload),
        result=result,
        bus=bus,
    )
