"""What each adapter is told to do: small frozen settings, handed down by the config.

The config validates its ``http:``, ``mqtt:`` and ``modbus:`` sections with pydantic and
turns each into one of these dataclasses, the way it turns a bus into a
:class:`~fcmaster.bus.plan.LinePlan`; an adapter never sees pydantic or the file. The
defaults are the config's defaults (a unit test holds them together), so a test or a tool
can build an adapter from the few settings it cares about.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal


@dataclass(slots=True, frozen=True)
class Token:
    """A bearer token of ``http.tokens`` and the role it grants."""

    name: str
    role: Literal["viewer", "operator"]
    secret: str


@dataclass(slots=True, frozen=True, kw_only=True)
class HttpSettings:
    """The HTTP API, dashboard and metrics listener (``http:``)."""

    listen: str = "127.0.0.1:8080"
    tokens: tuple[Token, ...] = ()
    anonymous: Literal["none", "viewer"] = "none"
    cors_origins: tuple[str, ...] = ()


@dataclass(slots=True, frozen=True, kw_only=True)
class TlsSettings:
    """TLS for the MQTT connection: CA, client certificate and key files."""

    ca: str | None = None
    cert: str | None = None
    key: str | None = None
    insecure: bool = False


@dataclass(slots=True, frozen=True, kw_only=True)
class MqttSettings:
    """The MQTT bridge (``mqtt:``); ``url`` is ``mqtt://host[:port]`` or ``mqtts://…``."""

    url: str = "mqtt://127.0.0.1:1883"
    base_topic: str = "fcmaster"
    status_topic: str | None = None  # None: {base_topic}/status
    client_id: str | None = None  # None: fcmaster-{hostname}-{digest of base topic, lines}
    username: str | None = None
    password: str | None = None
    tls: TlsSettings | None = None
    heartbeat_s: float = 60.0
    deadband_pct: float = 0.5
    discovery: bool = False
    discovery_prefix: str = "homeassistant"
    keepalive_s: int = 30
    reconnect_min_s: float = 1.0
    reconnect_max_s: float = 60.0
    commands: bool = False
    trust_broker: bool = False  # commands need no token: the broker's ACLs decide


@dataclass(slots=True, frozen=True, kw_only=True)
class SparkplugSettings:
    """The Sparkplug B edge node (``sparkplug:``); its own session on the broker at ``url``.

    ``store`` is the store-and-forward file (None: in memory, lost at a restart), bounded by
    ``store_max_mb`` and ``store_max_days``; ``bdSeq`` is kept in a file beside it.
    """

    group_id: str
    edge_node_id: str
    url: str = "mqtt://127.0.0.1:1883"
    primary_host_id: str | None = None  # None: publish without waiting for a host's STATE
    commands: bool = False
    store: str | None = None
    store_max_mb: float = 100.0
    store_max_days: float = 7.0
    client_id: str | None = None  # None: fcmaster-spb-{group_id}-{edge_node_id}
    username: str | None = None
    password: str | None = None
    tls: TlsSettings | None = None
    keepalive_s: int = 30
    reconnect_min_s: float = 1.0
    reconnect_max_s: float = 60.0
    rebirth_min_s: float = 5.0  # Rebirth requests closer together than this are ignored


@dataclass(slots=True, frozen=True, kw_only=True)
class ModbusSettings:
    """The Modbus TCP server (``modbus:``).

    ``units`` gives each drive's unit id by drive name (``modbus_unit``, else its address),
    already checked to be unique; ``allow`` lists the addresses or networks that may
    connect (None: this machine only).
    """

    units: Mapping[str, int]
    listen: str = "127.0.0.1:5020"
    allow: tuple[str, ...] | None = None
    commands: bool = False


# The security policies and modes an OPC UA endpoint may offer, as the config writes them:
# the policy's name from its URI (…/SecurityPolicy#Basic256Sha256) and the message mode.
OPCUA_SECURITY = (
    "Basic256Sha256:SignAndEncrypt",
    "Basic256Sha256:Sign",
    "Aes256_Sha256_RsaPss:SignAndEncrypt",
    "Aes256_Sha256_RsaPss:Sign",
    "Aes128_Sha256_RsaOaep:SignAndEncrypt",
    "Aes128_Sha256_RsaOaep:Sign",
    "None",
)
OPCUA_DEFAULT_SECURITY = ("Basic256Sha256:SignAndEncrypt", "Aes256_Sha256_RsaPss:SignAndEncrypt")


@dataclass(slots=True, frozen=True, kw_only=True)
class OpcuaSettings:
    """The OPC UA server (``opcua:``); ``pki`` is resolved against the config's folder.

    ``users`` are the tokens of ``http.tokens``: a user name is a token's name, its password
    the token.
    """

    listen: str = "127.0.0.1:4840"
    pki: str = "/var/lib/fcmaster/pki"
    security: tuple[str, ...] = OPCUA_DEFAULT_SECURITY
    anonymous: bool = False
    commands: bool = False
    users: tuple[Token, ...] = ()


def modbus_listen(text: str) -> tuple[str, int | None]:
    """``"127.0.0.1:5020"`` or ``"[::1]:5020"`` → host and port (None if not a number)."""
    text = text.strip()
    if text.startswith("["):
        host, _, rest = text[1:].partition("]")
        port = rest[1:] if rest.startswith(":") else ""
    else:
        host, _, port = text.rpartition(":") if text.count(":") == 1 else (text, "", "")
    return host, int(port) if port.isdigit() else None
