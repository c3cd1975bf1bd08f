"""The HTTP API as a FastAPI application: routes, roles, and outcome → status.

Every route reads the daemon through the :class:`~fcmaster.adapters.gateway.Gateway` only.
Reads come from the fleet state in memory; commands and parameter access go through
``gateway.execute`` and answer once the command has its one result, with the HTTP status
of :data:`OUTCOME_STATUS` and the result JSON (``outcome``, ``reason``, …) as the body.
Refusals before a command reaches a line (no or wrong token, a viewer's command, a
malformed body) are logged as ``http.command_refused`` with the actor and the reason; a
command refused for what it says (malformed, beyond limits, no such drive) is also audited
as ``command.completed`` with its values, the line the bus gives every command that reaches
it, with the same actor. How a request's body, caller and refusals are read lives in
:mod:`fcmaster.adapters.api_requests`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Final

from fastapi import Body, FastAPI, Query, Request, WebSocket
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import Response
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException

from fcmaster import __version__
from fcmaster.adapters import config_metrics, metrics
from fcmaster.adapters.api_requests import (
    Operator,
    StrictJsonRoute,
    Viewer,
    actor_of,
    describe_error,
    log_refused,
    peek_action,
    peek_payload,
    refused_command,
)
from fcmaster.adapters.auth import Authenticator, AuthError, Principal, Role
from fcmaster.adapters.command_json import parse_command, refusal
from fcmaster.adapters.gateway import Gateway
from fcmaster.adapters.messages import event_json
from fcmaster.adapters.middleware import (
    BodyLimit,
    SecurityHeaders,
    StopsOnly,
    error_body,
    json_response,
    states_json,
)
from fcmaster.adapters.parameter_sets import (
    Pace,
    ReadFailed,
    drift,
    fleet_drift,
    read_drive_set,
)
from fcmaster.adapters.readlimit import ReadsBusy, ViewerReads
from fcmaster.adapters.schemas import (
    CommandUnion,
    DriveOut,
    ErrorOut,
    LineOut,
    ParameterOut,
    ParameterWrite,
    PrincipalOut,
    ResultOut,
)
from fcmaster.adapters.stream import StreamRegistry, serve_stream
from fcmaster.bus.commands import Command, CommandResult, Outcome
from fcmaster.errors import UsageError
from fcmaster.health import gc_pauses
from fcmaster.journal import KINDS, MAX_LIMIT, parse_since
from fcmaster.protocol.parameter_set import ParameterSet
from fcmaster.state import AvailabilityChanged, CommandCompleted, ConditionChanged, rfc3339

STATIC: Final = Path(__file__).resolve().parent / "static"
MAX_BODY_BYTES: Final = 64 * 1024

OUTCOME_STATUS: Final = {
    Outcome.DONE: 200,  # carried out
    Outcome.REFUSED: 409,  # the drive said no (its error code in "error"): a state conflict
    Outcome.NOT_ALLOWED: 403,  # monitor-only drive, or beyond the drive's configured limits
    Outcome.INVALID: 422,  # malformed, or a parameter the protocol cannot address
    Outcome.SUPERSEDED: 409,  # a newer command replaced it before it reached the wire
    Outcome.TIMEOUT: 504,  # the drive did not answer after the line's retries
    Outcome.UNCONFIRMED: 504,  # acknowledged, but the status did not show the result in time
    Outcome.CANCELLED: 503,  # shutdown, line down or lost
}

DESCRIPTION: Final = """\
The fcmaster daemon's API: the fleet's drive states, commands, parameter access, line
statistics, an event stream (WebSocket `/api/v1/stream`) and Prometheus metrics (`/metrics`).

**Tokens.** Send `Authorization: Bearer <token>`. A `viewer` token reads; an `operator`
token also commands drives and writes parameters. Without tokens configured, or with
`http.anonymous: viewer`, reads from this machine's loopback need no token. The WebSocket
also takes the token as `?token=`, since browsers cannot set its headers.

**Commands** answer once the command has its one result; the status follows its outcome:

| outcome | status | meaning |
|---|---|---|
| `done` | 200 | carried out (`value`, `unit`, `raw` for reads) |
| `refused` | 409 | the drive said no; `error` has its code and text |
| `superseded` | 409 | a newer command replaced it before it reached the wire (`reason` names it) |
| `not_allowed` | 403 | monitor-only drive, or beyond its configured limits (`reason` names them) |
| `invalid` | 422 | malformed, or a parameter the protocol cannot address |
| `timeout` | 504 | no answer from the drive after the line's retries |
| `unconfirmed` | 504 | acknowledged, but the status did not show the result (`reason` says why) |
| `cancelled` | 503 | the daemon is shutting down or the line is down |

A 401 means no or an unknown token, a 403 without `outcome` a role too low for the request,
a 404 an unknown drive, a 400 a body that is not JSON text, a 413 one over 64 KiB. A
viewer's parameter reads are spaced out per line (they share the line with the poll); a 429
says too many are already waiting there.
"""

_AUTH_ERRORS: Final[dict[int | str, dict[str, Any]]] = {
    401: {"model": ErrorOut, "description": "No token, or not a known one"},
}
_DRIVE_ERRORS: Final[dict[int | str, dict[str, Any]]] = {
    **_AUTH_ERRORS,
    404: {"model": ErrorOut, "description": "No drive of that name"},
    422: {"model": ResultOut | ErrorOut, "description": "Malformed request"},
}
_COMMAND_ERRORS: Final[dict[int | str, dict[str, Any]]] = {
    **_DRIVE_ERRORS,
    400: {"model": ErrorOut, "description": "The body is not JSON text"},
    403: {"model": ResultOut | ErrorOut, "description": "not_allowed, or not an operator"},
    409: {"model": ResultOut, "description": "refused by the drive"},
    413: {"model": ErrorOut, "description": "Body too large"},
    503: {"model": ResultOut, "description": "cancelled"},
    504: {"model": ResultOut, "description": "timeout"},
}


def result_response(result: CommandResult, **extra: Any) -> Response:
    """A command result with the status of its outcome."""
    return json_response({**result.to_json(), **extra}, OUTCOME_STATUS[result.outcome])


def create_app(
    gateway: Gateway,
    auth: Authenticator,
    *,
    metrics_enabled: bool = True,
    cors_origins: tuple[str, ...] = (),
    streams: StreamRegistry | None = None,
) -> FastAPI:
    """The API for ``gateway``, guarded by ``auth``."""
    app = FastAPI(
        title="fcmaster",
        version=__version__,
        description=DESCRIPTION,
        openapi_url="/api/v1/openapi.json",
        docs_url=None,  # Swagger UI and ReDoc load from a CDN; the dashboard loads nothing
        redoc_url=None,
    )
    app.router.route_class = StrictJsonRoute
    registry = streams if streams is not None else StreamRegistry()
    viewer_reads = ViewerReads(gateway.clock)
    app.state.auth = auth

    async def run(
        name: str, payload: dict[str, Any], principal: Principal, **extra: Any
    ) -> Response:
        """Validate ``payload`` as a command for drive ``name``, carry it out, answer."""
        plan = gateway.drive_plan(name)
        state = gateway.fleet.find(name)
        if plan is None or state is None:
            reason = f"no drive called {name!r}"
            no_drive = CommandResult(outcome=Outcome.INVALID, reason=reason)
            refused_command(principal.name, name, payload, no_drive, None)
            raise HTTPException(404, reason)
        try:
            command: Command = parse_command(payload, plan, actor=principal.name)
        except UsageError as exc:
            result = refusal(exc)
            refused_command(principal.name, name, payload, result, state.bus)
            return result_response(result, **extra)
        return result_response(await gateway.execute(name, command), **extra)

    # -- errors ------------------------------------------------------------------------

    @app.exception_handler(AuthError)
    async def _autherror_body(request: Request, exc: AuthError) -> Response:
        if request.method in ("POST", "PUT") and not exc.counted:  # wrong tokens: in aggregate
            log_refused(
                exc.actor,
                request.path_params.get("name"),
                await peek_action(request),
                "forbidden" if exc.status == 403 else "unauthorized",
                exc.reason,
            )
        headers = {"WWW-Authenticate": "Bearer"} if exc.status == 401 else None
        if exc.retry_after_s:
            headers = {"Retry-After": str(max(1, round(exc.retry_after_s)))}
        return json_response(error_body(exc.reason), exc.status, headers=headers)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> Response:
        errors = jsonable_encoder(exc.errors())
        reason = "; ".join(describe_error(e) for e in errors)
        if request.method in ("POST", "PUT"):
            name = str(request.path_params.get("name"))
            state = gateway.fleet.find(name)
            invalid = CommandResult(outcome=Outcome.INVALID, reason=reason)
            payload = await peek_payload(request)
            param = request.path_params.get("param")
            if request.method == "PUT" and param is not None:  # a parameter write's body
                body = payload if isinstance(payload, dict) else {}
                payload = {**body, "action": "write", "parameter": param}
            bus = None if state is None else state.bus
            refused_command(actor_of(auth, request), name, payload, invalid, bus)
        return json_response({"outcome": "invalid", **error_body(reason, errors)}, 422)

    @app.exception_handler(HTTPException)
    async def _httperror_body(request: Request, exc: HTTPException) -> Response:
        return json_response(error_body(str(exc.detail)), exc.status_code, headers=exc.headers)

    # -- reads -------------------------------------------------------------------------

    @app.get("/api/v1/drives", response_model=list[DriveOut], responses=_AUTH_ERRORS)
    async def drives(_: Viewer, bus: str | None = None) -> Response:
        """Every drive's state, in configuration order (``bus``: one line's only)."""
        states = [s for s in gateway.fleet.snapshot() if bus is None or s.bus == bus]
        return Response(await states_json(states), media_type="application/json")

    @app.get(
        "/api/v1/drives/{name}",
        response_model=DriveOut,
        responses={**_AUTH_ERRORS, 404: _DRIVE_ERRORS[404]},
    )
    async def drive(name: str, _: Viewer) -> Response:
        """One drive's state."""
        state = gateway.fleet.find(name)
        if state is None:
            raise HTTPException(404, f"no drive called {name!r}")
        return json_response(state.to_json())

    @app.get("/api/v1/buses", response_model=list[LineOut], responses=_AUTH_ERRORS)
    async def buses(_: Viewer) -> Response:
        """Every line with its statistics (histogram buckets end at ``le: "+Inf"``)."""
        return json_response([line.to_json() for line in gateway.lines()])

    @app.get("/api/v1/status", responses=_AUTH_ERRORS)
    async def status(_: Viewer) -> Response:
        """The daemon: its version, its config (hash, loaded_at, last_reload), its OPC UA server.

        ``opcua`` is null without an ``opcua:`` section, else its ``listen``, whether its
        server process is ``up``, its ``restarts``, and its ``sessions`` (``user``, null for
        anonymous; ``client``, ``application``, ``security``, ``since``).
        """
        body = {"version": __version__, "config": gateway.config_status()}
        return json_response(body | {"opcua": gateway.opcua_status()})

    @app.get(
        "/api/v1/events",
        responses={
            **_AUTH_ERRORS,
            422: {"model": ErrorOut, "description": "A bad since, kind or limit"},
        },
    )
    async def events(
        _: Viewer,
        since: str | None = None,
        drive: str | None = None,
        kind: str | None = None,
        limit: Annotated[int, Query(ge=1, le=MAX_LIMIT)] = 100,
    ) -> Response:
        """The journal: the newest ``limit`` records matching, oldest first.

        ``since``: a time (RFC 3339) or an age (``30m``, ``2h``, ``7d``); ``kind``: one of
        command, alarm, warning, online, offline, watchdog, line_up, line_down, reload,
        start, stop.
        """
        try:
            after = None if since is None else parse_since(since, gateway.clock.wall())
        except ValueError as exc:
            raise HTTPException(422, f"since: {exc}") from None
        if kind is not None and kind not in KINDS:
            raise HTTPException(422, f"kind: {kind!r} is not one of {', '.join(KINDS)}")
        records = await gateway.events(since=after, kind=kind, drive=drive, limit=limit)
        return json_response(records)

    @app.get("/api/v1/drives/{name}/history", responses={**_AUTH_ERRORS, 404: _DRIVE_ERRORS[404]})
    async def drive_history(name: str, _: Viewer) -> Response:
        """The drive's last 15 minutes: samples as columns, and its recent events.

        ``t`` and one ``data`` list per series, the shape charts take; ``events`` are stream
        messages (alarms, availability, commands) with their time ``at``.
        """
        state = gateway.fleet.find(name)
        if state is None:
            raise HTTPException(404, f"no drive called {name!r}")
        history = gateway.fleet.history
        events = [
            {"at": rfc3339(at), **event_json(event)}
            for at, event in history.events(state.key)
            if isinstance(event, ConditionChanged | AvailabilityChanged | CommandCompleted)
        ]
        return json_response({"drive": name, **history.drive(state.key), "events": events})

    @app.get("/api/v1/buses/{name}/history", responses={**_AUTH_ERRORS, 404: _DRIVE_ERRORS[404]})
    async def bus_history(name: str, _: Viewer) -> Response:
        """The line's recent rates (15 min): requests, replies, timeouts, errors per second."""
        if all(line.name != name for line in gateway.lines()):
            raise HTTPException(404, f"no line called {name!r}")
        return json_response({"bus": name, **gateway.fleet.history.line(name)})

    @app.get("/api/v1/buses/{name}/frames", responses={**_AUTH_ERRORS, 404: _DRIVE_ERRORS[404]})
    async def bus_frames(name: str, _: Viewer, since: Annotated[int, Query(ge=0)] = 0) -> Response:
        """The line's recent frames (a ring of the last few thousand), from number ``since``.

        Each frame has its number ``seq``, direction ``dir`` (``tx``: the master's request,
        ``rx``: bytes the master read), ``time`` (Unix seconds), ``mono`` (the daemon's
        monotonic seconds) and ``data`` (hex). Ask again with ``since`` = ``next`` to
        follow the line without gaps; ``missed`` counts the frames that had left the ring.
        """
        found = gateway.line_frames(name, since)
        if found is None:
            raise HTTPException(404, f"no line called {name!r}")
        plan, got = found
        frames = [
            {"seq": seq, "dir": direction, "time": wall, "mono": mono, "data": data.hex()}
            for seq, direction, mono, wall, data in got.frames
        ]
        return json_response(
            {
                "bus": plan.name,
                "protocol": plan.protocol,
                "baudrate": plan.baudrate,
                "databits": plan.databits,
                "parity": plan.parity,
                "stopbits": plan.stopbits,
                "next": got.next,
                "missed": got.missed,
                "frames": frames,
            }
        )

    @app.get("/api/v1/whoami", response_model=PrincipalOut, responses=_AUTH_ERRORS)
    async def whoami(principal: Viewer) -> Response:
        """The caller's name and role, as the API sees them."""
        return json_response({"name": principal.name, "role": principal.role.name.lower()})

    # -- commands ----------------------------------------------------------------------

    @app.post("/api/v1/drives/{name}/commands", response_model=ResultOut, responses=_COMMAND_ERRORS)
    async def command(
        name: str, body: Annotated[CommandUnion, Body(discriminator="action")], principal: Operator
    ) -> Response:
        """Carry out a command; answers its one result (status by outcome)."""
        extra = {} if body.id is None else {"id": body.id}
        payload = body.model_dump(exclude_none=True, exclude={"id"})
        return await run(name, payload, principal, **extra)

    @app.get(
        "/api/v1/drives/{name}/parameters/{param}",
        response_model=ParameterOut,
        responses={k: v for k, v in _COMMAND_ERRORS.items() if k not in (400, 413)},
    )
    async def read_parameter(
        name: str,
        param: str,
        principal: Viewer,
        index: Annotated[int, Query(ge=0, le=65535)] = 0,
    ) -> Response:
        """Read a parameter, named as the drive's manual writes it (e.g. ``16-13``)."""
        payload = {"action": "read", "parameter": param, "index": index}
        state = gateway.fleet.find(name)
        if principal.can(Role.OPERATOR) or state is None:
            return await run(name, payload, principal, parameter=param, index=index)
        try:
            async with viewer_reads.turn(state.bus):
                return await run(name, payload, principal, parameter=param, index=index)
        except ReadsBusy as exc:
            reason = f"{exc}: try again shortly"
            return json_response(error_body(reason), 429, headers={"Retry-After": "1"})

    @app.put(
        "/api/v1/drives/{name}/parameters/{param}",
        response_model=ParameterOut,
        responses=_COMMAND_ERRORS,
    )
    async def write_parameter(
        name: str,
        param: str,
        body: ParameterWrite,
        principal: Operator,
        index: Annotated[int, Query(ge=0, le=65535)] = 0,
    ) -> Response:
        """Write a parameter (``persist``: to non-volatile memory too)."""
        payload = {
            "action": "write",
            "parameter": param,
            "index": index,
            "value": body.value,
            "persist": body.persist,
        }
        return await run(name, payload, principal, parameter=param, index=index)

    # -- parameter sets ----------------------------------------------------------------

    def pace(principal: Principal) -> Pace | None:
        """A viewer's reads take turns of the line's viewer-read spacing; an operator's not."""
        return None if principal.can(Role.OPERATOR) else viewer_reads.turn

    async def current_set(name: str, principal: Principal) -> ParameterSet | Response:
        try:
            return await read_drive_set(gateway, name, actor=principal.name, pace=pace(principal))
        except KeyError:
            raise HTTPException(404, f"no drive called {name!r}") from None
        except ReadFailed as failed:
            return result_response(failed.result, parameter=failed.parameter)
        except ReadsBusy as exc:
            reason = f"{exc}: try again shortly"
            return json_response(error_body(reason), 429, headers={"Retry-After": "1"})

    @app.get(
        "/api/v1/drives/{name}/parameters",
        responses={k: v for k, v in _COMMAND_ERRORS.items() if k not in (400, 403, 413)},
    )
    async def parameter_set(name: str, principal: Viewer) -> Response:
        """The drive's parameter set: identity and every writable parameter, read now.

        Read one parameter at a time as ordinary reads, behind the line's idle poll (a
        viewer's at the line's viewer-read pace, so a set takes seconds). The
        body has the form of an ``fcmaster params backup`` file; a parameter the drive
        refuses to read carries ``refused`` with the drive's code instead of a value.
        """
        found = await current_set(name, principal)
        return found if isinstance(found, Response) else json_response(found.to_dict())

    @app.post(
        "/api/v1/drives/{name}/parameters/diff",
        responses={k: v for k, v in _COMMAND_ERRORS.items() if k != 403},
    )
    async def parameter_drift(
        name: str, body: Annotated[dict[str, Any], Body()], principal: Viewer
    ) -> Response:
        """The drive against a saved set (a backup file as JSON): what differs now."""
        try:
            saved = ParameterSet.from_dict(body, source="the body")
        except UsageError as exc:
            return json_response({"outcome": "invalid", **error_body(str(exc))}, 422)
        found = await current_set(name, principal)
        if isinstance(found, Response):
            return found
        if saved.protocol != found.protocol:
            reason = f"a {saved.protocol} set for a {found.protocol} drive"
            return json_response({"outcome": "invalid", **error_body(reason)}, 422)
        return json_response(drift(name, saved, found))

    @app.post(
        "/api/v1/parameters/diff",
        responses={k: v for k, v in _COMMAND_ERRORS.items() if k != 403},
    )
    async def fleet_parameter_drift(
        body: Annotated[dict[str, Any], Body()], principal: Viewer
    ) -> Response:
        """Each drive named in the body (``{drive: saved set, …}``) against its set."""
        try:
            report = await fleet_drift(gateway, body, actor=principal.name, pace=pace(principal))
        except UsageError as exc:
            return json_response({"outcome": "invalid", **error_body(str(exc))}, 422)
        return json_response(report)

    # -- metrics, stream, dashboard ----------------------------------------------------

    if metrics_enabled:

        @app.get(
            "/metrics",
            response_class=Response,
            responses={200: {"content": {metrics.CONTENT_TYPE: {}}}, **_AUTH_ERRORS},
        )
        async def metrics_page(_: Viewer) -> Response:
            """Prometheus metrics (text exposition format 0.0.4), from the state in memory."""
            text = await metrics.render_async(
                gateway.fleet.snapshot(), gateway.lines(), gateway.hub, gc_pauses=gc_pauses()
            )
            text += config_metrics.render(gateway.config_status())
            return Response(text, media_type=metrics.CONTENT_TYPE)

    @app.websocket("/api/v1/stream")
    async def stream(websocket: WebSocket) -> None:
        await serve_stream(websocket, gateway, auth, registry, cors_origins=cors_origins)

    index_html = (STATIC / "index.html").read_bytes()

    @app.get("/", include_in_schema=False)
    async def dashboard() -> Response:
        return Response(index_html, media_type="text/html; charset=utf-8", headers=_PAGE_HEADERS)

    app.mount("/static", StaticFiles(directory=STATIC), name="static")
    app.add_middleware(SecurityHeaders)
    if cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=list(cors_origins),
            allow_methods=["GET", "POST", "PUT"],
            allow_headers=["Authorization", "Content-Type"],
        )
    app.add_middleware(StopsOnly)
    app.add_middleware(BodyLimit, limit=MAX_BODY_BYTES)
    return app


_PAGE_HEADERS: Final = {
    "Content-Security-Policy": (
        "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
        "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
    ),
    "Cache-Control": "no-cache",
}
