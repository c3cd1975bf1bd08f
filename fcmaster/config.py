"""The YAML configuration: pydantic models at the edge, plain plans handed down.

Loading happens in three passes, and every pass reports *every* problem it finds, each as a
``(key path, reason)`` pair such as ``("buses[0].drives[3].address", "131 is outside
1-126")``, so a user fixes a file in one go:

1. YAML syntax and ``${ENV_VAR}`` substitution (``${VAR:-default}`` gives a default);
2. structure: unknown keys, missing keys and wrong types (pydantic, ``extra="forbid"``);
3. meaning: names and addresses unique, addresses in range for the protocol and format,
   monitor parameters that the protocol can address, limits that make sense.

The result is a :class:`Config` whose lines are :class:`~fcmaster.bus.plan.LinePlan`
dataclasses; nothing below ``service`` ever sees pydantic.
"""

from __future__ import annotations

import contextlib
import ipaddress
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal
from urllib.parse import urlsplit

import yaml
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    TypeAdapter,
    ValidationError,
    field_validator,
    model_validator,
)

from fcmaster.adapters.auth import listen_problem
from fcmaster.bus.codecs import codec_for, with_protocol_delay
from fcmaster.bus.plan import DrivePlan, LinePlan, OnStart, WatchdogPlan
from fcmaster.bus.poll_round import poll_round_s
from fcmaster.bus.watchdog import WATCHDOGS
from fcmaster.errors import ConfigError, UsageError
from fcmaster.protocol.codec import DriveCodec
from fcmaster.protocol.watchdog import check_timeout

# Port URLs the master can drive: the simulator, serial device servers (raw TCP, RFC 2217)
# and pyserial's local helpers; anything else would fail only when the line first opens.
_PORT_SCHEMES = ("sim", "socket", "rfc2217", "loop", "spy", "hwgrep", "alt")
_ENC_KEYS = ("address_encoding", "response_encoding", "fault_encoding")
_ENV = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)(?::-([^}]*))?\}")


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class WatchdogModel(_Model):
    """A drive's ``watchdog``: the communication watchdog fcmaster gives it at adoption."""

    timeout_s: float
    action: str | None = None  # None: the protocol's first action (FC: stop; others: trip)


class DriveModel(_Model):
    """One drive under ``buses[].drives``."""

    name: str = Field(min_length=1)
    address: int
    control: Literal["bus", "monitor"] = "monitor"
    on_start: Literal["adopt", "stop"] = "adopt"
    nominal_frequency_hz: float = Field(default=50.0, gt=0)
    min_frequency_hz: float = Field(default=0.0, ge=0)
    max_frequency_hz: float | None = Field(default=None, gt=0)
    monitor: list[str] | None = None
    modbus_unit: int | None = Field(default=None, ge=1, le=247)  # None: the bus address
    # seconds the status may take to show a start's or stop's result (None: a default)
    confirm_s: float | None = Field(default=None, gt=0, le=600)
    watchdog: WatchdogModel | None = None


class BusModel(_Model):
    """One line under ``buses``."""

    name: str = Field(min_length=1)
    port: str = Field(min_length=1)
    protocol: Literal["danfoss-fc", "mitsubishi", "enc"] = "danfoss-fc"
    baudrate: int = Field(default=19200, gt=0)
    parity: Literal["N", "E", "O"] = "E"
    stopbits: Literal[1, 2] = 1
    databits: Literal[7, 8] = 8
    address_format: Literal[31, 126] = 126
    timeout_s: float | None = Field(default=None, gt=0)
    retries: int = Field(default=1, ge=0, le=10)
    pause_s: float | None = Field(default=None, ge=0)
    response_delay_ms: float = Field(default=10.0, ge=0)
    offline_after: int = Field(default=3, ge=1)
    probe_interval_s: float = Field(default=5.0, gt=0)
    # the most of the line's time probes of absent drives may take while others answer
    probe_share: float = Field(default=0.1, gt=0, le=0.5)
    echo: bool = False
    rs485: bool = False
    terminator: Literal["none", "cr", "crlf"] = "cr"  # mitsubishi: as the drive's Pr.124
    # mitsubishi: the waiting-time digit every request carries (0-150 ms in 10 ms steps), or
    # null when the drives' Pr.123 sets it and requests leave it out
    wait_time_ms: int | None = Field(default=0, ge=0, le=150, multiple_of=10)
    # enc: how the drives write addresses of 10 and above, response codes and fault codes
    # (protocols/enc.md §10 questions 1, 2 and 7); replies are read in either encoding
    address_encoding: Literal["hex", "decimal"] = "hex"
    response_encoding: Literal["hex", "decimal"] = "hex"
    fault_encoding: Literal["hex", "decimal"] = "hex"
    simulation: dict[str, Any] | None = None  # sim:// ports: what the simulated drives do
    drives: list[DriveModel] = Field(default_factory=list)


class TokenModel(_Model):
    """A bearer token and the role it grants."""

    name: str = Field(min_length=1)
    role: Literal["viewer", "operator"]
    token: str = Field(min_length=16)


class HttpModel(_Model):
    """The HTTP API, dashboard and metrics listener."""

    listen: str = "127.0.0.1:8080"
    tokens: list[TokenModel] = Field(default_factory=list)
    anonymous: Literal["none", "viewer"] = "none"
    cors_origins: list[str] = Field(default_factory=list)


class TlsModel(_Model):
    """TLS for the MQTT connection."""

    ca: str | None = None
    cert: str | None = None
    key: str | None = None
    insecure: bool = False


class MqttModel(_Model):
    """The MQTT bridge."""

    url: str = "mqtt://127.0.0.1:1883"  # mqtt://host[:1883] or mqtts://host[:8883]
    base_topic: str = "fcmaster"
    status_topic: str | None = None  # None: {base_topic}/status; one per gateway on a shared base
    client_id: str | None = None
    username: str | None = None
    password: str | None = None
    tls: TlsModel | None = None
    heartbeat_s: float = Field(default=60.0, gt=0)
    deadband_pct: float = Field(default=0.5, ge=0)
    discovery: bool = False
    discovery_prefix: str = "homeassistant"
    keepalive_s: int = Field(default=30, ge=5, le=3600)
    reconnect_min_s: float = Field(default=1.0, gt=0)
    reconnect_max_s: float = Field(default=60.0, gt=0)
    # Commands over MQTT: off unless switched on; then each payload carries an operator
    # token of http.tokens ("token"), unless the broker's ACLs alone decide who may publish.
    commands: bool = False
    trust_broker: bool = False

    @field_validator("url")
    @classmethod
    def _check_url(cls, url: str) -> str:
        parts = urlsplit(url)
        if parts.scheme not in ("mqtt", "mqtts"):
            raise ValueError("use mqtt://host:port or mqtts://host:port")
        if not parts.hostname:
            raise ValueError("the URL names no host")
        if parts.username is not None or parts.password is not None:
            raise ValueError("put credentials in mqtt.username and mqtt.password")
        _ = parts.port  # raises ValueError for a port that is not a number in range
        return url

    @model_validator(mode="after")
    def _check_tls(self) -> MqttModel:
        if self.tls is not None and urlsplit(self.url).scheme != "mqtts":
            raise ValueError("a tls section needs an mqtts:// url (mqtt:// is plain TCP)")
        if self.tls is not None and self.tls.key is not None and self.tls.cert is None:
            raise ValueError("tls.key belongs to a client certificate: give tls.cert too")
        if self.reconnect_min_s > self.reconnect_max_s:
            raise ValueError("reconnect_min_s is above reconnect_max_s")
        return self

    @field_validator("base_topic", "status_topic", "discovery_prefix")
    @classmethod
    def _check_topic(cls, topic: str | None) -> str | None:
        if topic is not None and (
            not topic.strip("/") or set(topic) & {"+", "#"} or topic != topic.strip("/")
        ):
            raise ValueError("a topic without wildcards (+, #) or a leading or trailing /")
        return topic


def _cidr(text: str) -> str:
    try:
        ipaddress.ip_network(text, strict=False)
    except ValueError:
        raise ValueError(f"{text!r} is not an address or network like 10.0.0.0/8") from None
    return text


class ModbusModel(_Model):
    """The Modbus TCP server for PLCs and SCADA (read-only unless ``commands: true``)."""

    listen: str = "127.0.0.1:5020"
    # Who may connect (addresses or CIDR networks); None: this machine only. Modbus has no
    # authentication, so listening beyond loopback needs this list.
    allow: list[Annotated[str, AfterValidator(_cidr)]] | None = None
    commands: bool = False

    @field_validator("listen")
    @classmethod
    def _check_listen(cls, listen: str) -> str:
        host, port = modbus_listen(listen)
        if not host or port is None or not 0 <= port <= 65535:
            raise ValueError("write it like 127.0.0.1:5020 or [::1]:5020")
        return listen


def modbus_listen(text: str) -> tuple[str, int | None]:
    """``"127.0.0.1:5020"`` or ``"[::1]:5020"`` → host and port (None if not a number)."""
    text = text.strip()
    if text.startswith("["):
        host, _, rest = text[1:].partition("]")
        port = rest[1:] if rest.startswith(":") else ""
    else:
        host, _, port = text.rpartition(":") if text.count(":") == 1 else (text, "", "")
    return host, int(port) if port.isdigit() else None


def _is_loopback(host: str) -> bool:
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class MetricsModel(_Model):
    """Prometheus metrics at /metrics on the HTTP listener."""

    enabled: bool = True


class LoggingModel(_Model):
    """Log level and format (auto: console on a terminal, JSON otherwise)."""

    level: Literal["debug", "info", "warning", "error"] = "info"
    format: Literal["auto", "json", "console"] = "auto"


class ConfigModel(_Model):
    """The whole file."""

    buses: list[BusModel] = Field(min_length=1)
    http: HttpModel | None = None
    mqtt: MqttModel | None = None
    modbus: ModbusModel | None = None
    metrics: MetricsModel | None = None
    logging: LoggingModel = LoggingModel()
    on_shutdown: Literal["hold", "stop"] = "hold"


@dataclass(slots=True, frozen=True)
class Config:
    """A validated configuration: plans for the lines, models for the adapters."""

    lines: tuple[LinePlan, ...]
    model: ConfigModel
    path: Path | None = None


def load(path: Path | str, *, buses_only: bool = False) -> Config:
    """Read, substitute, validate and convert a config file; ConfigError lists every problem.

    ``buses_only``: for a reader of the ``buses`` alone (the simulator), an unset
    environment variable outside them (a token, a broker password) is not a problem.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError([(str(path), f"cannot read: {exc.strerror or exc}")]) from exc
    return parse(text, path=path, buses_only=buses_only)


def parse(
    text: str,
    *,
    path: Path | None = None,
    env: dict[str, str] | None = None,
    buses_only: bool = False,
) -> Config:
    """Validate config text (see :func:`load`)."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else "YAML"
        raise ConfigError([(where, f"not valid YAML: {getattr(exc, 'problem', exc)}")]) from exc
    if not isinstance(data, dict):
        raise ConfigError([("(top)", "the file must be a mapping with a 'buses' list")])
    unset: list[tuple[str, str]] = []
    data = _substitute(data, "", os.environ if env is None else env, unset)
    problems: list[tuple[str, str]] = []
    if buses_only:  # stand-ins long enough to pass validation; never used
        unset = [p for p in unset if p[0] == "buses" or p[0].startswith(("buses.", "buses["))]
    lines: tuple[LinePlan, ...] = ()
    try:
        model = ConfigModel.model_validate(data)
    except ValidationError as exc:
        problems = [_describe(error) for error in exc.errors()]
        # Check the meaning of whatever parts are well-formed too, so that a wrong type in
        # one bus does not hide an address out of range in another until it is fixed.
        salvaged = _salvage(data)
        if salvaged is not None:
            partial, renumber = salvaged
            more: list[tuple[str, str]] = []
            _check(partial, more)
            problems += [(renumber(path), renumber(reason)) for path, reason in more]
    else:
        lines = _check(model, problems)
    if unset:  # what an unset variable left empty is not a problem of its own
        blank = {where for where, _ in unset}
        problems = unset + [(where, why) for where, why in problems if where not in blank]
    if problems:
        raise ConfigError(problems)
    return Config(lines=lines, model=model, path=path)


_DRIVE_PATH = re.compile(r"\bbuses\[(\d+)\](?:\.drives\[(\d+)\])?")


def _salvage(data: dict[str, Any]) -> tuple[ConfigModel, Callable[[str], str]] | None:
    """The well-formed parts of a file that failed validation, and where they came from.

    The function maps a key path in the parts back to the file's own (the buses and drives
    kept are renumbered).
    """
    buses = data.get("buses")
    if not isinstance(buses, list):
        return None
    kept: list[BusModel] = []
    where: list[tuple[int, list[int]]] = []  # per kept bus: its index, its drives' indices
    for b, bus in enumerate(buses):
        if not isinstance(bus, dict):
            continue
        drives = bus.get("drives", [])
        if not isinstance(drives, list):
            drives = []  # reported already: the bus's other keys can still be checked
        good = [d for d, drive in enumerate(drives) if _valid(DriveModel, drive)]
        try:
            kept.append(BusModel.model_validate({**bus, "drives": [drives[d] for d in good]}))
        except (ValidationError, TypeError):
            continue
        where.append((b, good))
    sections: dict[str, Any] = {}
    for name, field in ConfigModel.model_fields.items():
        if name != "buses" and name in data:
            with contextlib.suppress(ValidationError):  # reported already: its rules wait
                sections[name] = TypeAdapter[Any](field.annotation or Any).validate_python(
                    data[name]
                )
    partial = ConfigModel.model_construct(buses=kept, **sections)

    def original(match: re.Match[str]) -> str:
        b, goods = where[int(match[1])]
        drive = "" if match[2] is None else f".drives[{goods[int(match[2])]}]"
        return f"buses[{b}]{drive}"

    def renumber(text: str) -> str:
        return _DRIVE_PATH.sub(original, text)

    return partial, renumber


def _valid(model: type[BaseModel], value: Any) -> bool:
    try:
        model.model_validate(value)
    except ValidationError:
        return False
    return True


def _substitute(value: Any, path: str, env: Any, problems: list[tuple[str, str]]) -> Any:
    if isinstance(value, str):

        def replace(match: re.Match[str]) -> str:
            name, default = match[1], match[2]
            if name in env:
                return str(env[name])
            if default is not None:
                return default
            problems.append((path or "(top)", f"environment variable {name} is not set"))
            return f"unset-{name}".ljust(_UNSET_LENGTH, "-")

        return _ENV.sub(replace, value)
    if isinstance(value, dict):
        return {k: _substitute(v, _join(path, k), env, problems) for k, v in value.items()}
    if isinstance(value, list):
        return [_substitute(v, f"{path}[{i}]", env, problems) for i, v in enumerate(value)]
    return value


_UNSET_LENGTH = 32  # an unset variable's stand-in passes a token's length check


def _join(path: str, key: object) -> str:
    return f"{path}.{key}" if path else str(key)


def _location(loc: tuple[int | str, ...]) -> str:
    out = ""
    for part in loc:
        out = f"{out}[{part}]" if isinstance(part, int) else _join(out, part)
    return out or "(top)"


def _describe(error: Any) -> tuple[str, str]:
    loc = tuple(p for p in error["loc"] if not (isinstance(p, str) and p.startswith("function-")))
    kind, given = error["type"], error.get("input")
    if kind == "extra_forbidden":
        return _location(loc), "unknown key"
    if kind == "missing":
        return _location(loc), "required key is missing"
    if kind == "literal_error":
        expected = error.get("ctx", {}).get("expected", "")
        return _location(loc), f"{given!r} is not one of {expected}"
    return _location(loc), f"{error['msg'].lower()} (got {given!r})"


def _check(model: ConfigModel, problems: list[tuple[str, str]]) -> tuple[LinePlan, ...]:
    lines: list[LinePlan] = []
    drive_names: dict[str, str] = {}
    bus_names: dict[str, str] = {}
    ports: dict[str, str] = {}
    for b, bus in enumerate(model.buses):
        where = f"buses[{b}]"
        _unique(bus_names, bus.name, f"{where}.name", "bus name", problems)
        _unique(ports, bus.port, f"{where}.port", "port", problems)
        port_problem = _port_problem(bus.port)
        if port_problem:
            problems.append((f"{where}.port", port_problem))
        codec = codec_for(_line(bus, ()))
        addresses: dict[str, str] = {}
        drives: list[DrivePlan] = []
        for d, drive in enumerate(bus.drives):
            at = f"{where}.drives[{d}]"
            _unique(drive_names, drive.name, f"{at}.name", "drive name", problems)
            if drive.address not in codec.addresses:
                problems.append((f"{at}.address", _bad_address(bus, drive.address, codec)))
            else:
                _unique(addresses, str(drive.address), f"{at}.address", "address", problems)
            for m, parameter in enumerate(drive.monitor or ()):
                try:
                    # Named right, and readable by one poll (a Mitsubishi parameter is not).
                    codec.poll_sequence((codec.parameter(parameter),))
                except UsageError as exc:
                    problems.append((f"{at}.monitor[{m}]", str(exc)))
            max_hz = drive.max_frequency_hz or drive.nominal_frequency_hz
            if drive.min_frequency_hz > max_hz:
                problems.append(
                    (
                        f"{at}.min_frequency_hz",
                        f"{drive.min_frequency_hz} is above the maximum {max_hz}",
                    )
                )
            drives.append(
                DrivePlan(
                    name=drive.name,
                    address=drive.address,
                    control=drive.control == "bus",
                    on_start=OnStart(drive.on_start),
                    monitor=None if drive.monitor is None else tuple(drive.monitor),
                    nominal_frequency_hz=drive.nominal_frequency_hz,
                    min_frequency_hz=drive.min_frequency_hz,
                    max_frequency_hz=max_hz,
                    confirm_s=drive.confirm_s,
                    watchdog=_watchdog(bus, drive, at, problems),
                )
            )
        if bus.protocol != "danfoss-fc" and "address_format" in bus.model_fields_set:
            problems.append((f"{where}.address_format", "only danfoss-fc lines have one"))
        for key in _ENC_KEYS:
            if bus.protocol != "enc" and key in bus.model_fields_set:
                problems.append((f"{where}.{key}", "only enc lines have one"))
        for key in ("terminator", "wait_time_ms"):
            if bus.protocol != "mitsubishi" and key in bus.model_fields_set:
                problems.append((f"{where}.{key}", "only mitsubishi lines have one"))
        line = _line(bus, tuple(drives))
        _watchdogs_outlast_round(line, where, problems)
        lines.append(line)
    # Names are HTTP path segments (/api/v1/drives/{name}) and MQTT topic levels
    # ({base}/{bus}/{drive}/state) whichever surfaces are on today: a name must work on all.
    for b, bus in enumerate(model.buses):
        _addressable(bus.name, f"buses[{b}].name", problems)
        for d, drive in enumerate(bus.drives):
            _addressable(drive.name, f"buses[{b}].drives[{d}].name", problems)
    if model.modbus is not None:
        modbus_units(model, problems)
        host, _ = modbus_listen(model.modbus.listen)
        if not model.modbus.allow and not _is_loopback(host):  # [] lets no PLC in either
            problems.append(
                (
                    "modbus.listen",
                    f"{model.modbus.listen} reaches beyond this machine and Modbus has no "
                    "authentication: list the PLCs' addresses in modbus.allow "
                    "(e.g. [10.0.5.0/24]) or listen on 127.0.0.1",
                )
            )
    for b, bus in enumerate(model.buses):
        if bus.port.startswith("sim://"):  # what `run` builds the simulated line from
            from fcmaster.clock import MonotonicClock
            from fcmaster.sim.service import sim_line

            try:  # built as `run` builds it: settings a simulated drive cannot take too
                sim_line(lines[b], bus.simulation or {}, clock=MonotonicClock())
            except ConfigError as exc:
                problems.extend(exc.problems)
    if model.mqtt is not None and model.mqtt.tls is not None:
        for key in ("ca", "cert", "key"):
            file = getattr(model.mqtt.tls, key)
            if file is not None and not os.access(file, os.R_OK):
                problems.append((f"mqtt.tls.{key}", f"cannot read {file}"))
    mqtt = model.mqtt
    if mqtt is not None and mqtt.commands and not mqtt.trust_broker:
        operators = [t for t in (model.http.tokens if model.http else ()) if t.role == "operator"]
        if not operators:
            problems.append(
                (
                    "mqtt.commands",
                    "each MQTT command must carry an operator token of http.tokens, and there "
                    "is none: add one, or set mqtt.trust_broker: true if the broker's ACLs "
                    "alone decide who may publish commands",
                )
            )
    if model.http is not None:
        problem = listen_problem(model.http.listen, has_tokens=bool(model.http.tokens))
        if problem:  # the rule `run` applies as it starts the API
            problems.append(("http.listen", problem))
        secrets: dict[str, str] = {}
        for t, token in enumerate(model.http.tokens):
            path = f"http.tokens[{t}].token"
            if token.token in secrets:  # never echo a secret into a message
                problems.append((path, f"the same token is already used at {secrets[token.token]}"))
            secrets.setdefault(token.token, path)
    return tuple(lines)


def modbus_units(model: ConfigModel, problems: list[tuple[str, str]]) -> dict[str, int]:
    """Each drive's Modbus unit id (``modbus_unit``, else its bus address), by drive name.

    A unit id names one drive across every bus, so a clash (two lines that both have an
    address 1) is a problem for ``problems``, with the fix.
    """
    units: dict[str, int] = {}
    seen: dict[int, str] = {}
    for b, bus in enumerate(model.buses):
        for d, drive in enumerate(bus.drives):
            where = f"buses[{b}].drives[{d}]"
            unit = drive.address if drive.modbus_unit is None else drive.modbus_unit
            if not 1 <= unit <= 247:
                problems.append(
                    (
                        f"{where}.modbus_unit",
                        f"address {unit} is no Modbus unit id (1-247): set modbus_unit",
                    )
                )
                continue
            key = f"{where}.modbus_unit" if drive.modbus_unit is not None else f"{where}.address"
            if unit in seen:
                problems.append(
                    (
                        f"{where}.modbus_unit",
                        f"Modbus unit {unit} is already taken by {seen[unit]}: set a "
                        "modbus_unit of its own on one of them",
                    )
                )
                continue
            seen[unit] = f"{drive.name} ({key})"
            units[drive.name] = unit
    return units


def _line(bus: BusModel, drives: tuple[DrivePlan, ...]) -> LinePlan:
    plan = LinePlan(
        name=bus.name,
        port=bus.port,
        protocol=bus.protocol,
        baudrate=bus.baudrate,
        parity=bus.parity,
        stopbits=bus.stopbits,
        databits=bus.databits,
        address_format=bus.address_format,
        timeout_s=bus.timeout_s,
        retries=bus.retries,
        pause_s=bus.pause_s,
        response_delay_s=bus.response_delay_ms / 1000.0,
        offline_after=bus.offline_after,
        probe_interval_s=bus.probe_interval_s,
        probe_share=bus.probe_share,
        echo=bus.echo,
        rs485=bus.rs485,
        terminator=bus.terminator,
        wait_time_ms=bus.wait_time_ms,
        address_encoding=bus.address_encoding,
        response_encoding=bus.response_encoding,
        fault_encoding=bus.fault_encoding,
        drives=drives,
    )
    if "response_delay_ms" in bus.model_fields_set:
        return plan
    # Where the protocol says how long its drives may take (Mitsubishi: the waiting time
    # plus the data check), the reply deadline is derived from it.
    return with_protocol_delay(plan)


def _watchdog(
    bus: BusModel, drive: DriveModel, at: str, problems: list[tuple[str, str]]
) -> WatchdogPlan | None:
    """The drive's ``watchdog`` as a plan; its problems, each at its key, into ``problems``."""
    wanted = drive.watchdog
    if wanted is None:
        return None
    facts = WATCHDOGS[bus.protocol]
    action = wanted.action or facts.actions[0]
    found = len(problems)
    if drive.control != "bus":
        problems.append(
            (f"{at}.watchdog", "fcmaster writes the watchdog only of a `control: bus` drive")
        )
    if action not in facts.actions:
        problems.append(
            (
                f"{at}.watchdog.action",
                f"{action!r} is not an action of {bus.protocol} drives' watchdog "
                f"(one of: {', '.join(facts.actions)})",
            )
        )
    else:
        try:
            check_timeout(facts, wanted.timeout_s, action)
        except UsageError as exc:
            problems.append((f"{at}.watchdog.timeout_s", str(exc)))
    return WatchdogPlan(wanted.timeout_s, action) if len(problems) == found else None


def _watchdogs_outlast_round(line: LinePlan, where: str, problems: list[tuple[str, str]]) -> None:
    """A configured watchdog shorter than the line's worst-case poll round would trip."""
    if not any(drive.watchdog for drive in line.drives):
        return
    try:
        round_s = poll_round_s(line)[0]
    except UsageError:  # a monitor list the drive loop has already reported
        return
    for d, drive in enumerate(line.drives):
        if drive.watchdog is not None and drive.watchdog.timeout_s < round_s:
            problems.append(
                (
                    f"{where}.drives[{d}].watchdog.timeout_s",
                    f"{drive.watchdog.timeout_s:g} s is shorter than the line's worst-case "
                    f"poll round of {round_s * 1000:.1f} ms: normal polling would trip the drive",
                )
            )


def _port_problem(port: str) -> str:
    """What is wrong with a port URL ("" for a device path or a URL the master can open)."""
    scheme, separator, _rest = port.partition("://")
    if not separator:
        return ""
    if scheme not in _PORT_SCHEMES:
        listed = ", ".join(f"{s}://" for s in _PORT_SCHEMES)
        return f"{scheme}:// is not a port this master can open (use a device path or {listed})"
    if scheme in ("socket", "rfc2217"):
        try:
            parts = urlsplit(port)
            if not parts.hostname or parts.port is None:
                raise ValueError
        except ValueError:
            return f"use {scheme}://host:port (got {port!r})"
    return ""


def _unique(
    seen: dict[str, str], value: str, path: str, what: str, problems: list[tuple[str, str]]
) -> None:
    if value in seen:
        problems.append((path, f"{what} {value!r} is already used at {seen[value]}"))
    else:
        seen[value] = path


_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")


def _addressable(name: str, path: str, problems: list[tuple[str, str]]) -> None:
    """A drive or bus name every surface can address: no /, +, #, %, spaces, ``..``."""
    if not _NAME.fullmatch(name):
        problems.append(
            (
                path,
                f"{name!r} cannot be addressed over HTTP and MQTT: use 1-64 letters, digits, "
                "'-', '_' and '.', starting with a letter or digit",
            )
        )


def _bad_address(bus: BusModel, address: int, codec: DriveCodec) -> str:
    reason = f"{address} is outside {_span(codec.addresses)}"
    if bus.protocol == "enc" and address in (0, 127):
        # F2.15 allows 0-127, but fcmaster sends its broadcasts to 127 and means broadcast
        # by address 0 between its layers, so neither can name one drive.
        return f"{reason}: set the drive's F2.15 to another address (0 and 127 are broadcast)"
    if bus.protocol == "enc" and bus.address_encoding == "decimal":
        return f"{reason}: with address_encoding decimal an address has two decimal digits"
    return reason


def _span(addresses: range) -> str:
    return f"{addresses.start}-{addresses.stop - 1}"
