"""The HTTP API's request bodies and the documented shapes of its answers (pydantic).

Request bodies are strict (no "30" for 30, no true for 1, no NaN, no unknown keys), so a
malformed body is a 422 that names the field before anything reaches a line. The command
body is a union keyed by ``action``, so the OpenAPI document says which fields each action
takes. What the models cannot say (both ``frequency_hz`` and ``reference_pct`` given, a
parameter the protocol cannot address) the shared :func:`~fcmaster.adapters.parse_command`
and the bus refuse, with a reason.

Response models only document: handlers answer the dicts of ``DriveState.to_json`` and
``CommandResult.to_json`` directly, which stay the one source of the public JSON, and the
API's schema test checks the two agree.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)


_Id = Annotated[str | int | None, Field(description="echoed in the result, as over MQTT")]
_Hz = Annotated[float | None, Field(description="Hz; what 100 % means is the drive's nominal")]
_Pct = Annotated[float | None, Field(description="% of the drive's nominal frequency")]
_Parameter = Annotated[
    str | int,
    Field(description='as the drive\'s manual writes it, e.g. "16-13"', examples=["16-13"]),
]
_Index = Annotated[int, Field(ge=0, le=65535, description="array index (0 for plain ones)")]


class MotionCommand(_Body):
    """A command without arguments."""

    action: Literal["stop", "coast", "quick_stop", "reset", "forward", "reverse", "jog"]
    id: _Id = None


class StartCommand(_Body):
    """Run, optionally at a new reference (give frequency_hz or reference_pct)."""

    action: Literal["start"]
    frequency_hz: _Hz = None
    reference_pct: _Pct = None
    id: _Id = None


class SetReferenceCommand(_Body):
    """Change the reference without changing the motion (frequency_hz or reference_pct)."""

    action: Literal["set_reference"]
    frequency_hz: _Hz = None
    reference_pct: _Pct = None
    id: _Id = None


class ReadCommand(_Body):
    """Read a parameter."""

    action: Literal["read"]
    parameter: _Parameter
    index: _Index = 0
    id: _Id = None


class WriteCommand(_Body):
    """Write a parameter (``persist``: to non-volatile memory too)."""

    action: Literal["write"]
    parameter: _Parameter
    index: _Index = 0
    value: float
    persist: bool = False
    id: _Id = None


CommandUnion = MotionCommand | StartCommand | SetReferenceCommand | ReadCommand | WriteCommand


class ParameterWrite(_Body):
    """The body of ``PUT …/parameters/{param}``."""

    value: float
    persist: bool = False


# -- answers (documentation) ---------------------------------------------------------------


class ValueOut(BaseModel):
    """One measured value."""

    value: float | str
    unit: str
    name: str = Field(description='the manual\'s name, e.g. "Motor Current" ("" if unknown)')
    updated_at: str | None = Field(description="RFC 3339 UTC time this value was read")


class ConditionOut(BaseModel):
    """An active alarm or warning."""

    code: int
    text: str


class DriveOut(BaseModel):
    """One drive's state, the JSON every surface shows (DESIGN.md "Drive state")."""

    name: str
    bus: str
    address: int
    protocol: str
    online: bool
    control: Literal["bus", "monitor"]
    running: bool
    fault: bool
    warning: bool
    direction: Literal["forward", "reverse"]
    at_reference: bool
    output_frequency_hz: float | None
    output_frequency_updated_at: str | None = Field(
        description="RFC 3339 UTC time the output frequency was read (may precede updated_at)"
    )
    reference_pct: float | None
    status_word: int | None
    status_bits: list[str] = Field(
        description="the status word's set bits, named as the protocol's manual names them"
    )
    values: dict[str, ValueOut]
    alarms: list[ConditionOut]
    warnings: list[ConditionOut]
    updated_at: str | None = Field(description="RFC 3339 UTC time of the last good reply")


class DriveErrorOut(BaseModel):
    """The drive's refusal."""

    code: int
    text: str


class ResultOut(BaseModel):
    """A command's one result (outcome → HTTP status: see the API description)."""

    outcome: Literal["done", "refused", "timeout", "not_allowed", "invalid", "cancelled"]
    reason: str
    value: float | str | None = None
    unit: str | None = None
    raw: int | None = None
    error: DriveErrorOut | None = None
    id: str | int | None = None


class ParameterOut(ResultOut):
    """A parameter read or write: the result with the parameter and index it was for."""

    parameter: str
    index: int


class AdapterOut(BaseModel):
    """The serial adapter behind a local port, as the machine names it."""

    device: str = Field(description="the tty, e.g. /dev/ttyUSB0")
    driver: str | None = Field(description="the kernel driver: ftdi_sio, ch341-uart, cp210x, …")
    by_id: str | None = Field(description="its /dev/serial/by-id name")
    by_path: str | None = Field(description="its /dev/serial/by-path name")
    latency_ms: int | None = Field(description="its latency timer (null: it has none)")


class LineOut(BaseModel):
    """One line: its port, whether it is up, its drives and its statistics."""

    name: str
    port: str
    protocol: str
    baudrate: int
    up: bool
    drives: list[str]
    stats: dict[str, object] = Field(description="counters and histograms (le '+Inf' as text)")
    adapter: AdapterOut | None = Field(
        None, description="the USB serial adapter of a local port, once opened (else null)"
    )


class PrincipalOut(BaseModel):
    """Who the API takes the caller for."""

    name: str
    role: Literal["viewer", "operator"]


class ErrorOut(BaseModel):
    """Why a request was refused before it reached a drive."""

    detail: object
    reason: str
