"""The YAML configuration: pydantic models at the edge, plain plans handed down.

Loading happens in three passes, and every pass reports *every* problem it finds, each as a
``(key path, reason)`` pair such as ``("buses[0].drives[3].address", "131 is outside
1-126")``, so a user fixes a file in one go:

1. YAML syntax (no key given twice, nesting and aliases bounded: :func:`.config_yaml.read`)
   and ``${ENV_VAR}`` substitution (``${VAR:-default}`` gives a default);
2. structure: unknown keys, missing keys and wrong types (pydantic, ``extra="forbid"``);
3. meaning: names and addresses unique, addresses in range for the protocol and format,
   monitor parameters that the protocol can address, limits that make sense.

The result is a :class:`Config` whose lines are :class:`~fcmaster.bus.plan.LinePlan`
dataclasses and each adapter gets its settings (:mod:`fcmaster.adapters.settings`);
nothing below ``service`` ever sees pydantic. The adapter sections' models live in
:mod:`fcmaster.config_sections` (the Modbus checks over every bus in
:mod:`fcmaster.config_modbus`), the YAML helpers in :mod:`fcmaster.config_yaml`;
a protocol's own line keys (``address_format``, ``terminator``, …) and the protocol names
come from the protocol specs (:mod:`fcmaster.protocol.registry`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from pydantic import (
    Field,
    TypeAdapter,
    ValidationError,
    create_model,
    model_validator,
)

from fcmaster.adapters.auth import listen_problem
from fcmaster.adapters.settings import (
    HttpSettings,
    ModbusSettings,
    MqttSettings,
    OpcuaSettings,
    SparkplugSettings,
    Token,
)
from fcmaster.bus.codecs import codec_for, with_protocol_delay
from fcmaster.bus.plan import DrivePlan, LinePlan, OnStart
from fcmaster.config_hints import in_words
from fcmaster.config_modbus import check_modbus, modbus_units
from fcmaster.config_opcua import check_opcua
from fcmaster.config_profiles import drive_profile, profile_monitor
from fcmaster.config_salvage import Dropped, mend
from fcmaster.config_sections import (
    HttpModel,
    JournalModel,
    LoggingModel,
    MetricsModel,
    ModbusModel,
    MqttModel,
    OpcuaModel,
    SparkplugModel,
    TlsModel,
    TokenModel,
    listeners_apart,
)
from fcmaster.config_sections import StrictModel as _Model
from fcmaster.config_values import baudrate_problem, check_name, port_url_problem
from fcmaster.config_watchdog import WatchdogModel, watchdog_plan, watchdogs_outlast_round
from fcmaster.config_yaml import read, substitute
from fcmaster.errors import ConfigError, UsageError
from fcmaster.protocol.registry import DEFAULT, NAMES, line_keys, spec_for
from fcmaster.protocol.spec import LineKey
from fcmaster.store_settings import MEMORY, StoreSettings

__all__ = [
    "BusFields",
    "BusModel",
    "Config",
    "ConfigModel",
    "DriveModel",
    "HttpModel",
    "JournalModel",
    "LoggingModel",
    "MetricsModel",
    "ModbusModel",
    "MqttModel",
    "OpcuaModel",
    "SparkplugModel",
    "TlsModel",
    "TokenModel",
    "load",
    "parse",
]

if TYPE_CHECKING:
    ProtocolName = str
else:  # the registry's names, checked as a Literal so a wrong one lists the right ones
    ProtocolName = Literal[NAMES]


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
    # modbus-rtu: a built-in drive profile's name or a profile file (config_profiles)
    profile: str | None = Field(default=None, min_length=1)


class BusFields(_Model):
    """One line under ``buses``: the keys every protocol has (see :data:`BusModel`)."""

    name: str = Field(min_length=1)
    port: str = Field(min_length=1)
    protocol: ProtocolName = DEFAULT
    # Left out: the protocol's factory setting (see _factory_settings); these defaults
    # stand only for a bus whose protocol is unknown, which is refused anyway.
    baudrate: int = Field(default=9600, gt=0)
    parity: Literal["N", "E", "O"] = "E"
    stopbits: Literal[1, 2] = 1
    databits: Literal[7, 8] = 8
    timeout_s: float | None = Field(default=None, gt=0)
    retries: int = Field(default=1, ge=0, le=10)
    pause_s: float | None = Field(default=None, ge=0)
    response_delay_ms: float = Field(default=10.0, ge=0)
    offline_after: int = Field(default=3, ge=1)
    probe_interval_s: float = Field(default=5.0, gt=0)
    # the most of the line's time probes of absent drives may take while others answer
    probe_share: float = Field(default=0.08, gt=0, le=0.5)
    echo: bool = False
    rs485: bool = False
    simulation: dict[str, Any] | None = None  # sim:// ports: what the simulated drives do
    drives: list[DriveModel] = Field(default_factory=list)

    @model_validator(mode="before")
    @classmethod
    def _factory_settings(cls, data: Any) -> Any:
        """The serial settings a bus leaves out are its protocol's factory settings.

        As the CLI tools and the simulator take them, so a line that the drives' own
        defaults would make talk does so with none of the three keys written.
        """
        if not isinstance(data, dict):
            return data
        protocol = data.get("protocol", DEFAULT)
        if not isinstance(protocol, str) or protocol not in NAMES:
            return data  # refused by the field, with the names that are known
        factory = spec_for(protocol).factory
        defaults = {"baudrate": factory.baudrate, "parity": factory.parity}
        return {**defaults, "stopbits": factory.stopbits, **data}


def _line_key_field(key: LineKey) -> Any:
    """A protocol's own line key as a pydantic field: its allowed values and default."""
    if key.choices:
        return (Literal[key.choices], key.default)  # Literal[(31, 126)] is Literal[31, 126]
    number = Field(default=key.default, ge=key.minimum, le=key.maximum, multiple_of=key.step)
    return (int | None if key.nullable else int, number)


if TYPE_CHECKING:
    BusModel = BusFields
else:
    # One line under ``buses``: the common keys plus every protocol's own line keys (a bus
    # of another protocol that sets one is told so by the meaning pass).
    BusModel = create_model(
        "BusModel",
        __base__=BusFields,
        __doc__="One line under ``buses``.",
        **{key.name: _line_key_field(key) for key, _ in line_keys()},
    )


class ConfigModel(_Model):
    """The whole file."""

    buses: list[BusModel] = Field(min_length=1)
    http: HttpModel | None = None
    mqtt: MqttModel | None = None
    modbus: ModbusModel | None = None
    opcua: OpcuaModel | None = None
    sparkplug: SparkplugModel | None = None
    metrics: MetricsModel | None = None
    journal: JournalModel | None = None
    logging: LoggingModel = LoggingModel()
    on_shutdown: Literal["hold", "stop"] = "hold"
    # The most a shutdown waits for stops and commands to end; within it, only as long as
    # the commanded drives' ramps need (service.py). Service managers must allow more.
    shutdown_timeout_s: float = Field(default=60.0, gt=0, le=3600)


@dataclass(slots=True, frozen=True)
class Config:
    """A validated configuration: plans for the lines, settings for the adapters.

    ``model`` is the file as validated, for the CLI and the service; adapters are handed
    :attr:`http`, :attr:`mqtt` and :attr:`modbus` (None: the section is absent).
    """

    lines: tuple[LinePlan, ...]
    model: ConfigModel
    path: Path | None = None

    @property
    def http(self) -> HttpSettings | None:
        """The HTTP adapter's settings."""
        return None if self.model.http is None else self.model.http.settings()

    @property
    def mqtt(self) -> MqttSettings | None:
        """The MQTT adapter's settings."""
        return None if self.model.mqtt is None else self.model.mqtt.settings()

    @property
    def sparkplug(self) -> SparkplugSettings | None:
        """The Sparkplug adapter's settings; a relative store path is from the file's folder."""
        model = self.model.sparkplug
        return None if model is None else model.settings(self._relative(model.store))

    @property
    def modbus(self) -> ModbusSettings | None:
        """The Modbus TCP adapter's settings, with every drive's unit id."""
        return (
            None if self.model.modbus is None else self.model.modbus.settings(self.modbus_units())
        )

    @property
    def opcua(self) -> OpcuaSettings | None:
        """The OPC UA server's settings: its pki folder resolved, its users from http.tokens."""
        model = self.model.opcua
        if model is None:
            return None
        http = self.model.http
        users = tuple(Token(t.name, t.role, t.token) for t in (http.tokens if http else ()))
        return model.settings(str(_beside(self.path, model.pki)), users)

    @property
    def journal(self) -> StoreSettings | None:
        """The journal's settings; a relative path is taken from the config file's folder."""
        model = self.model.journal
        if model is None:
            return None
        return StoreSettings(
            path=self._relative(model.path), max_mb=model.max_mb, max_days=model.max_days
        )

    def _relative(self, path: str | None) -> str | None:
        """A store's path: taken from the config file's folder when relative; None in memory."""
        if path is not None and path != MEMORY and self.path is not None:
            return str(Path(self.path).parent / path)  # an absolute path stays as it is
        return None if path == MEMORY else path

    def modbus_units(self) -> dict[str, int]:
        """Each drive's Modbus unit id by name; ConfigError if two drives would share one.

        ``load`` checks this only when the file has a ``modbus`` section; the register map
        of a file without one (``fcmaster modbus-map``) is checked here.
        """
        problems: list[tuple[str, str]] = []
        units = modbus_units(self.model.buses, problems)
        if problems:
            raise ConfigError(problems)
        return units


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
    twice: list[tuple[str, str]] = []  # keys given twice: reported with the rest
    data = read(text, twice)
    if not isinstance(data, dict):
        raise ConfigError([*twice, ("(top)", "the file must be a mapping with a 'buses' list")])
    unset: list[tuple[str, str]] = []
    data = substitute(data, "", os.environ if env is None else env, unset)
    problems: list[tuple[str, str]] = []
    if buses_only:  # stand-ins long enough to pass validation; never used
        unset = [p for p in unset if p[0] == "buses" or p[0].startswith(("buses.", "buses["))]
    lines: tuple[LinePlan, ...] = ()
    try:
        model = ConfigModel.model_validate(data)
    except ValidationError as exc:
        problems = [in_words(ConfigModel, error) for error in exc.errors()]
        # Check the meaning of whatever parts are well-formed too, so that a wrong type in
        # one bus does not hide an address out of range in another until it is fixed.
        salvaged = _salvage(data)
        if salvaged is not None:
            partial, renumber, dropped = salvaged
            more: list[tuple[str, str]] = []
            _check(partial, more, path)  # profile files beside the config, as in a good file
            problems += [
                (renumber(where), renumber(reason))
                for where, reason in more
                if dropped.believed(where)
            ]
    else:
        lines = _check(model, problems, path)
    if unset:  # what an unset variable left empty is not a problem of its own
        blank = {where for where, _ in unset}
        problems = unset + [(where, why) for where, why in problems if where not in blank]
    problems = twice + problems
    if problems:
        raise ConfigError(problems)
    return Config(lines=lines, model=model, path=path)


_DRIVE_PATH = re.compile(r"\bbuses\[(\d+)\](?:\.drives\[(\d+)\])?")


def _salvage(data: dict[str, Any]) -> tuple[ConfigModel, Callable[[str], str], Dropped] | None:
    """The well-formed parts of a file that failed validation, and where they came from.

    A bus or drive with wrong keys is kept without them (:func:`.config_salvage.mend`);
    :class:`.config_salvage.Dropped` says which, so that no check of a key left out is
    believed. The function maps a key path in the parts back to the file's own (the buses
    and drives kept are renumbered).
    """
    buses = data.get("buses")
    if not isinstance(buses, list):
        return None
    kept: list[BusModel] = []
    where: list[tuple[int, list[int]]] = []  # per kept bus: its index, its drives' indices
    dropped = Dropped()
    for b, bus in enumerate(buses):
        if not isinstance(bus, dict):
            continue
        drives = bus.get("drives", [])
        if not isinstance(drives, list):
            drives = []  # reported already: the bus's other keys can still be checked
        good: list[int] = []
        mended: list[DriveModel] = []
        left_out: list[frozenset[str]] = []
        for d, drive in enumerate(drives):
            if (fixed := mend(DriveModel, drive, drive=True)) is not None:
                good.append(d)
                mended.append(fixed[0])
                left_out.append(fixed[1])
        try:
            fixed_bus = mend(BusModel, {**bus, "drives": mended}, drive=False)
        except TypeError:
            continue
        if fixed_bus is None:
            continue
        kept.append(fixed_bus[0])
        where.append((b, good))
        moot = _addresses_depend(fixed_bus[0], fixed_bus[1])
        dropped.add_bus(fixed_bus[0], fixed_bus[1], left_out, addresses_moot=moot)
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

    return partial, renumber, dropped


def _addresses_depend(bus: BusModel, left_out: frozenset[str]) -> bool:
    """Whether ``bus``'s address range could differ had the keys ``left_out`` been written.

    Danfoss's address_format does change it, the Modbus line's profile does not: each value
    the key may take is tried.
    """
    if "protocol" in left_out:
        return True
    try:
        addresses = codec_for(_line(bus, ())).addresses
        for key, spec in line_keys():
            if spec.name != bus.protocol or key.name not in left_out:
                continue
            values = key.choices or (key.minimum, key.maximum)
            for value in (*values, None) if key.nullable else values:
                other = bus.model_copy(update={key.name: value})
                if codec_for(_line(other, ())).addresses != addresses:
                    return True
    except (UsageError, ValueError):  # a value no codec takes: nothing is known
        return True
    return False


def _check(
    model: ConfigModel, problems: list[tuple[str, str]], source: Path | None = None
) -> tuple[LinePlan, ...]:
    base = Path.cwd() if source is None else source.parent  # where profile files are found
    lines: list[LinePlan] = []
    drive_names: dict[str, tuple[str, str]] = {}
    bus_names: dict[str, tuple[str, str]] = {}
    ports: dict[str, str] = {}
    for b, bus in enumerate(model.buses):
        where = f"buses[{b}]"
        _unique_name(bus_names, bus.name, f"{where}.name", "bus name", problems)
        _unique(ports, bus.port, f"{where}.port", "port", problems)
        port_problem = port_url_problem(bus.port)
        if port_problem:
            problems.append((f"{where}.port", port_problem))
        spec = spec_for(bus.protocol)
        if bus.baudrate not in spec.baudrates:
            problems.append((f"{where}.baudrate", baudrate_problem(spec, bus.baudrate)))
        codec = codec_for(_line(bus, ()))
        addresses: dict[str, str] = {}
        drives: list[DrivePlan] = []
        for d, drive in enumerate(bus.drives):
            at = f"{where}.drives[{d}]"
            _unique_name(drive_names, drive.name, f"{at}.name", "drive name", problems)
            if drive.address not in codec.addresses:
                problems.append((f"{at}.address", spec.bad_address(bus, drive.address)))
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
            line_profile = getattr(bus, "profile", None)  # modbus-rtu: the line's own
            profile = drive_profile(bus.protocol, drive.profile, base, at, problems, line_profile)
            if profile is None and line_profile is not None:  # the line's serves the drive
                profile = drive_profile(bus.protocol, line_profile, base, at, [])
            drives.append(
                DrivePlan(
                    name=drive.name,
                    address=drive.address,
                    control=drive.control == "bus",
                    on_start=OnStart(drive.on_start),
                    monitor=profile_monitor(profile)
                    if drive.monitor is None
                    else tuple(drive.monitor),
                    nominal_frequency_hz=drive.nominal_frequency_hz,
                    min_frequency_hz=drive.min_frequency_hz,
                    max_frequency_hz=max_hz,
                    confirm_s=drive.confirm_s,
                    watchdog=watchdog_plan(
                        bus.protocol, drive.watchdog, drive.control, at, problems, profile
                    ),
                    profile=profile,
                )
            )
        problems.extend(_foreign_keys(bus, where))
        line = _line(bus, tuple(drives))
        watchdogs_outlast_round(line, where, problems)
        lines.append(line)
    # Names are HTTP path segments (/api/v1/drives/{name}) and MQTT topic levels
    # ({base}/{bus}/{drive}/state) whichever surfaces are on today: a name must work on all.
    for b, bus in enumerate(model.buses):
        check_name(bus.name, f"buses[{b}].name", problems)
        for d, drive in enumerate(bus.drives):
            check_name(drive.name, f"buses[{b}].drives[{d}].name", problems)
    if model.modbus is not None:
        check_modbus(model.modbus, model.buses, problems)
    if model.opcua is not None:
        check_opcua(model.opcua, model.http, _beside(source, model.opcua.pki), problems)
    servers = {"http": model.http, "modbus": model.modbus, "opcua": model.opcua}
    listens = {f"{k}.listen": None if v is None else v.listen for k, v in servers.items()}
    listeners_apart(listens, problems)
    for b, bus in enumerate(model.buses):
        if bus.port.startswith("sim://"):  # what `run` builds the simulated line from
            from fcmaster.clock import MonotonicClock
            from fcmaster.sim.service import sim_line

            try:  # built as `run` builds it: settings a simulated drive cannot take too
                sim_line(lines[b], bus.simulation or {}, clock=MonotonicClock())
            except ConfigError as exc:
                problems.extend(exc.problems)
    for section in (model.mqtt, model.sparkplug):
        if section is not None and section.tls is not None:
            name = "mqtt" if section is model.mqtt else "sparkplug"
            for key in ("ca", "cert", "key"):
                file = getattr(section.tls, key)
                if file is not None and not os.access(file, os.R_OK):
                    problems.append((f"{name}.tls.{key}", f"cannot read {file}"))
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


def _beside(source: Path | None, path: str) -> Path:
    """``path`` as written in the config: a relative one is taken from the file's folder."""
    return Path(path) if source is None else Path(source).parent / path


_PLAN_FIELDS = frozenset(field.name for field in dataclasses.fields(LinePlan))


def _line(bus: BusModel, drives: tuple[DrivePlan, ...]) -> LinePlan:
    keys = {key.name: getattr(bus, key.name) for key, _ in line_keys()}
    plan = LinePlan(
        name=bus.name,
        port=bus.port,
        protocol=bus.protocol,
        baudrate=bus.baudrate,
        parity=bus.parity,
        stopbits=bus.stopbits,
        databits=bus.databits,
        timeout_s=bus.timeout_s,
        retries=bus.retries,
        pause_s=bus.pause_s,
        response_delay_s=bus.response_delay_ms / 1000.0,
        offline_after=bus.offline_after,
        probe_interval_s=bus.probe_interval_s,
        probe_share=bus.probe_share,
        echo=bus.echo,
        rs485=bus.rs485,
        drives=drives,
        # every protocol's own keys (each bus model has them all, with their defaults): as
        # the plan's fields where it has them, else among its protocol_options
        **{name: value for name, value in keys.items() if name in _PLAN_FIELDS},
        protocol_options=tuple((n, v) for n, v in keys.items() if n not in _PLAN_FIELDS),
    )
    if "response_delay_ms" in bus.model_fields_set:
        return plan
    # Where the protocol says how long its drives may take (Mitsubishi: the waiting time
    # plus the data check), the reply deadline is derived from it.
    return with_protocol_delay(plan)


def _unique(
    seen: dict[str, str], value: str, path: str, what: str, problems: list[tuple[str, str]]
) -> None:
    if value in seen:
        problems.append((path, f"{what} {value!r} is already used at {seen[value]}"))
    else:
        seen[value] = path


def _unique_name(
    seen: dict[str, tuple[str, str]],
    name: str,
    path: str,
    what: str,
    problems: list[tuple[str, str]],
) -> None:
    """As :func:`_unique`, for names, where ``Pump1`` and ``pump1`` are the same name.

    A dashboard, a PLC tag list or a case-insensitive broker ACL would mix them up, and a
    command meant for one could reach the other.
    """
    key = name.casefold()
    if key not in seen:
        seen[key] = (name, path)
        return
    first, at = seen[key]
    if first == name:
        problems.append((path, f"{what} {name!r} is already used at {at}"))
    else:
        problems.append((path, f"{what} {name!r} differs only in case from {first!r} at {at}"))


def _foreign_keys(bus: BusModel, where: str) -> list[tuple[str, str]]:
    """Keys set on ``bus`` that belong to other protocols than its own."""
    owners: dict[str, list[str]] = {}
    for key, spec in line_keys():
        owners.setdefault(key.name, []).append(spec.name)
    return [
        (f"{where}.{name}", f"only {' or '.join(names)} lines have one")
        for name, names in owners.items()
        if bus.protocol not in names and name in bus.model_fields_set
    ]
