"""The config's adapter sections (HTTP, MQTT, Modbus TCP, OPC UA, metrics, logging).

Each model checks what it can alone (``extra="forbid"``, types, ranges, a URL's form); rules
that need the whole file (tokens that MQTT commands need, Modbus unit ids across buses) are
:mod:`fcmaster.config`'s.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Mapping
from typing import TYPE_CHECKING, Annotated, Final, Literal
from urllib.parse import urlsplit

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, field_validator, model_validator

from fcmaster.adapters.settings import (
    OPCUA_DEFAULT_SECURITY,
    OPCUA_SECURITY,
    HttpSettings,
    ModbusSettings,
    MqttSettings,
    OpcuaSettings,
    SparkplugSettings,
    TlsSettings,
    Token,
    modbus_listen,
)


class StrictModel(BaseModel):
    """A config section: unknown keys are errors, and the result cannot change."""

    model_config = ConfigDict(extra="forbid", frozen=True)


class TokenModel(StrictModel):
    """A bearer token and the role it grants."""

    name: str = Field(min_length=1)
    role: Literal["viewer", "operator"]
    token: str = Field(min_length=16)


class HttpModel(StrictModel):
    """The HTTP API, dashboard and metrics listener."""

    listen: str = "127.0.0.1:8080"
    tokens: list[TokenModel] = Field(default_factory=list)
    anonymous: Literal["none", "viewer"] = "none"
    cors_origins: list[str] = Field(default_factory=list)

    def settings(self) -> HttpSettings:
        """What the HTTP adapter is told."""
        return HttpSettings(
            listen=self.listen,
            tokens=tuple(Token(t.name, t.role, t.token) for t in self.tokens),
            anonymous=self.anonymous,
            cors_origins=tuple(self.cors_origins),
        )


class TlsModel(StrictModel):
    """TLS for the MQTT connection."""

    ca: str | None = None
    cert: str | None = None
    key: str | None = None
    insecure: bool = False


class MqttModel(StrictModel):
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
        return broker_url(url, "mqtt")

    @model_validator(mode="after")
    def _check_tls(self) -> MqttModel:
        check_connection(self.url, self.tls, self.reconnect_min_s, self.reconnect_max_s)
        return self

    def settings(self) -> MqttSettings:
        """What the MQTT adapter is told."""
        fields = self.model_dump(exclude={"tls"})
        tls = None if self.tls is None else TlsSettings(**self.tls.model_dump())
        return MqttSettings(**fields, tls=tls)

    @field_validator("base_topic", "status_topic", "discovery_prefix")
    @classmethod
    def _check_topic(cls, topic: str | None) -> str | None:
        if topic is not None and (
            not topic.strip("/") or set(topic) & {"+", "#"} or topic != topic.strip("/")
        ):
            raise ValueError("a topic without wildcards (+, #) or a leading or trailing /")
        return topic


def broker_url(url: str, section: str) -> str:
    """``url`` if it is ``mqtt://host[:port]`` or ``mqtts://…``; ValueError saying what to fix."""
    parts = urlsplit(url)
    if parts.scheme not in ("mqtt", "mqtts"):
        raise ValueError("use mqtt://host:port or mqtts://host:port")
    if not parts.hostname:
        raise ValueError("the URL names no host")
    if parts.username is not None or parts.password is not None:
        raise ValueError(f"put credentials in {section}.username and {section}.password")
    _ = parts.port  # raises ValueError for a port that is not a number in range
    return url


def check_connection(
    url: str, tls: TlsModel | None, reconnect_min_s: float, reconnect_max_s: float
) -> None:
    """The rules a broker connection's keys keep together; ValueError for the first broken."""
    if tls is not None and urlsplit(url).scheme != "mqtts":
        raise ValueError("a tls section needs an mqtts:// url (mqtt:// is plain TCP)")
    if tls is not None and tls.key is not None and tls.cert is None:
        raise ValueError("tls.key belongs to a client certificate: give tls.cert too")
    if reconnect_min_s > reconnect_max_s:
        raise ValueError("reconnect_min_s is above reconnect_max_s")


def _sparkplug_id(text: str) -> str:
    # Sparkplug 3.0, "Topic Namespace Elements": an id is a topic level, so never + / #
    if not text or set(text) & {"+", "/", "#"}:
        raise ValueError("a Sparkplug id is a non-empty topic level, without + / or #")
    return text


SparkplugId = Annotated[str, AfterValidator(_sparkplug_id)]


class SparkplugModel(StrictModel):
    """The Sparkplug B edge node: its own MQTT session, TLS and credentials as ``mqtt``."""

    url: str = "mqtt://127.0.0.1:1883"
    group_id: SparkplugId
    edge_node_id: SparkplugId
    primary_host_id: SparkplugId | None = None
    # DCMD obeyed only when switched on; the broker's ACLs then decide who may publish it.
    commands: bool = False
    store: str | None = Field(default=None, min_length=1)  # None: in memory
    store_max_mb: float = Field(default=100.0, gt=0)
    store_max_days: float = Field(default=7.0, gt=0)
    client_id: str | None = Field(default=None, min_length=1)
    username: str | None = None
    password: str | None = None
    tls: TlsModel | None = None
    keepalive_s: int = Field(default=30, ge=5, le=3600)
    reconnect_min_s: float = Field(default=1.0, gt=0)
    reconnect_max_s: float = Field(default=60.0, gt=0)
    rebirth_min_s: float = Field(default=5.0, ge=0)

    @field_validator("url")
    @classmethod
    def _check_url(cls, url: str) -> str:
        return broker_url(url, "sparkplug")

    @model_validator(mode="after")
    def _check_tls(self) -> SparkplugModel:
        check_connection(self.url, self.tls, self.reconnect_min_s, self.reconnect_max_s)
        return self

    def settings(self, store: str | None) -> SparkplugSettings:
        """What the Sparkplug adapter is told, with the store's path as resolved."""
        fields = self.model_dump(exclude={"tls", "store"})
        tls = None if self.tls is None else TlsSettings(**self.tls.model_dump())
        return SparkplugSettings(**fields, tls=tls, store=store)


def _cidr(text: str) -> str:
    try:
        ipaddress.ip_network(text, strict=False)
    except ValueError:
        raise ValueError(f"{text!r} is not an address or network like 10.0.0.0/8") from None
    return text


_EVERY_ADDRESS: Final = frozenset(("", "0.0.0.0", "::", "*"))


def listeners_apart(listens: dict[str, str | None], problems: list[tuple[str, str]]) -> None:
    """Two of the gateway's servers on one port: named now, not found as the daemon starts.

    ``listens`` maps each server's key (``opcua.listen``) to its address, None when off. One
    on every address meets any other on the same port.
    """
    taken: list[tuple[str, str, int]] = []
    for key, listen in listens.items():
        if listen is None:
            continue
        host, port = modbus_listen(listen)
        if port is None or port == 0:
            continue  # judged by the section itself
        for other, other_host, other_port in taken:
            if port == other_port and (host == other_host or {host, other_host} & _EVERY_ADDRESS):
                problems.append((key, f"port {port} is {other}'s too: give each server its own"))
                break
        taken.append((key, host, port))


def _listen_address(listen: str, port_example: int) -> str:
    """``listen`` if it is a host and a port (the example names the server's usual port)."""
    host, port = modbus_listen(listen)
    if not host or port is None or not 0 <= port <= 65535:
        raise ValueError(f"write it like 127.0.0.1:{port_example} or [::1]:{port_example}")
    return listen


class ModbusModel(StrictModel):
    """The Modbus TCP server for PLCs and SCADA (read-only unless ``commands: true``)."""

    listen: str = "127.0.0.1:5020"
    # Who may connect (addresses or CIDR networks); None: this machine only. Modbus has no
    # authentication, so listening beyond loopback needs this list.
    allow: list[Annotated[str, AfterValidator(_cidr)]] | None = None
    commands: bool = False

    @field_validator("listen")
    @classmethod
    def _check_listen(cls, listen: str) -> str:
        return _listen_address(listen, 5020)

    def settings(self, units: Mapping[str, int]) -> ModbusSettings:
        """What the Modbus adapter is told, with each drive's unit id (see ``modbus_units``)."""
        allow = None if self.allow is None else tuple(self.allow)
        return ModbusSettings(
            listen=self.listen, allow=allow, commands=self.commands, units=dict(units)
        )


if TYPE_CHECKING:
    SecurityName = str
else:  # the known names, checked as a Literal so a wrong one lists the right ones
    SecurityName = Literal[OPCUA_SECURITY]


class OpcuaModel(StrictModel):
    """The OPC UA server for SCADA (read-only unless ``commands: true``)."""

    listen: str = "127.0.0.1:4840"
    pki: str = Field(default="/var/lib/fcmaster/pki", min_length=1)
    security: list[SecurityName] = Field(
        default_factory=lambda: list(OPCUA_DEFAULT_SECURITY), min_length=1
    )
    anonymous: bool = False
    commands: bool = False

    @field_validator("listen")
    @classmethod
    def _check_listen(cls, listen: str) -> str:
        return _listen_address(listen, 4840)

    @field_validator("security")
    @classmethod
    def _check_security(cls, security: list[str]) -> list[str]:
        twice = sorted({s for s in security if security.count(s) > 1})
        if twice:
            raise ValueError(f"{', '.join(twice)} listed more than once")
        return security

    def settings(self, pki: str, users: tuple[Token, ...]) -> OpcuaSettings:
        """What the OPC UA adapter is told (``pki`` resolved, ``users`` from http.tokens)."""
        return OpcuaSettings(
            listen=self.listen,
            pki=pki,
            security=tuple(self.security),
            anonymous=self.anonymous,
            commands=self.commands,
            users=users,
        )


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a name or an address) is this machine only."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class MetricsModel(StrictModel):
    """Prometheus metrics at /metrics on the HTTP listener."""

    enabled: bool = True


class LoggingModel(StrictModel):
    """Log level and format (auto: console on a terminal, JSON otherwise)."""

    level: Literal["debug", "info", "warning", "error"] = "info"
    format: Literal["auto", "json", "console"] = "auto"


class JournalModel(StrictModel):
    """The journal of commands, alarms and lifecycle events (SQLite; no path: in memory)."""

    path: str | None = Field(default=None, min_length=1)
    max_mb: float = Field(default=100.0, gt=0)
    max_days: float = Field(default=90.0, gt=0)
