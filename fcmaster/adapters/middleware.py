"""ASGI pieces around the API: strict JSON answers, a body size limit, security headers."""

from __future__ import annotations

import asyncio
import json
import re
from collections.abc import Iterable
from typing import Any

from starlette.exceptions import HTTPException
from starlette.responses import Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from fcmaster.adapters.command_json import loads
from fcmaster.adapters.http_guard import RESERVE_KEY
from fcmaster.adapters.messages import json_safe
from fcmaster.state import DriveState

_COMMANDS = re.compile(r"/api/v1/drives/[^/]+/commands")


def json_response(content: Any, status_code: int = 200, **kwargs: Any) -> Response:
    """Strict JSON (no NaN or Infinity tokens: they become null and "+Inf")."""
    return Response(strict_json(content), status_code, media_type="application/json", **kwargs)


def strict_json(content: Any) -> str:
    """``content`` as JSON text that every parser accepts (see :func:`json_safe`)."""
    try:  # non-finite numbers are rare (histogram bounds): only then pay for the walk
        return json.dumps(content, ensure_ascii=False, allow_nan=False)
    except ValueError:
        return json.dumps(json_safe(content), ensure_ascii=False, allow_nan=False)


async def states_json(states: Iterable[DriveState], *, slice_size: int = 16) -> str:
    """Drive states as a JSON array, letting the event loop (the lines) run between slices.

    A fleet of 126 drives takes a few milliseconds to serialise; in slices of 16 the bus
    never waits for more than a fraction of one.
    """
    parts: list[str] = []
    for n, state in enumerate(states, 1):
        parts.append(strict_json(state.to_json()))
        if n % slice_size == 0:
            await asyncio.sleep(0)
    return "[" + ",".join(parts) + "]"


def error_body(reason: str, detail: Any = None) -> dict[str, Any]:
    """Why a request was refused: ``reason`` in words (``detail`` as FastAPI has it)."""
    return {"detail": reason if detail is None else detail, "reason": reason}


class BodyLimit:
    """413 for request bodies over ``limit`` bytes, before anything buffers them."""

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Refuse a body too large, or pass the request on with its body counted."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = dict(scope["headers"]).get(b"content-length", b"0")
        if not declared.isdigit() or int(declared) > self.limit:
            response = (
                json_response(error_body(f"the body is over {self.limit} bytes"), 413)
                if declared.isdigit()
                else json_response(error_body("Content-Length is not a number"), 400)
            )
            await response(scope, receive, send)
            return
        seen = 0

        async def limited() -> Message:
            nonlocal seen
            message = await receive()
            seen += len(message.get("body", b""))
            if seen > self.limit:
                raise HTTPException(413, f"the body is over {self.limit} bytes")
            return message

        await self.app(scope, limited, send)


class StopsOnly:
    """On a reserve connection (see ``http_guard``) only stop, coast and quick_stop pass."""

    URGENT = frozenset({"stop", "coast", "quick_stop"})

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Pass a stop (or anything on an ordinary connection) on; 503 for the rest."""
        if scope["type"] != "http" or not scope.get("state", {}).get(RESERVE_KEY):
            await self.app(scope, receive, send)
            return
        body = b""
        if scope["method"] == "POST" and _COMMANDS.fullmatch(scope["path"]):
            more = True
            try:
                while more:  # BodyLimit, outside, bounds it; the connection guard times it
                    message = await receive()
                    body += message.get("body", b"")
                    more = message.get("more_body", False) and message["type"] == "http.request"
                payload = loads(body)
            except (ValueError, HTTPException):  # not JSON, or too large
                payload = None
            if isinstance(payload, dict) and payload.get("action") in self.URGENT:
                await self.app(scope, replaying(body, receive), send)
                return
        reason = "the server is at its connection limit: only stop, coast and quick_stop are taken"
        response = json_response(
            {"outcome": "cancelled", **error_body(reason)}, 503, headers={"Retry-After": "1"}
        )
        await response(scope, receive, send)


def replaying(body: bytes, receive: Receive) -> Receive:
    """A ``receive`` that hands over ``body`` (already read) once, then ``receive``'s own."""
    given = False

    async def replay() -> Message:
        nonlocal given
        if given:
            return await receive()
        given = True
        return {"type": "http.request", "body": body, "more_body": False}

    return replay


class SecurityHeaders:
    """nosniff, no framing, no referrer on every answer."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Pass the request on, adding the headers to its answer."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                message["headers"] = [
                    *message.get("headers", ()),
                    (b"x-content-type-options", b"nosniff"),
                    (b"x-frame-options", b"DENY"),
                    (b"referrer-policy", b"no-referrer"),
                ]
            await send(message)

        await self.app(scope, receive, with_headers)
