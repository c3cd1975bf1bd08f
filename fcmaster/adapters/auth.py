"""Who is asking: bearer tokens with roles, and the loopback rules for anonymous reads.

Theory of operation
-------------------
Every token in ``http.tokens`` grants a role: ``viewer`` reads, ``operator`` also commands
drives and writes parameters (an operator is a viewer too). A request that carries
``Authorization: Bearer <token>`` is checked against every configured token in constant
time — the SHA-256 digests of both sides are compared with :func:`hmac.compare_digest`, and
every token is compared, so neither the position of a match nor a token's length shows in
the response time. A header that is present but wrong is always refused (401), never
treated as anonymous.

Without a header, a request is anonymous. Anonymous requests get the viewer role only
when anonymous reads are switched on (``http.anonymous: viewer``, or no tokens configured at
all: then the API is read-only) *and* the request comes from the loopback interface *and*
names a loopback host (``Host: 127.0.0.1:8080``, ``localhost``, ``[::1]``). The last check
keeps a web page in the operator's browser from reading the fleet through a DNS name that
it re-binds to 127.0.0.1.

Guessing is slowed and told in aggregate on the HTTP listener
(:class:`~fcmaster.adapters.auth_failures.FailedAuthentications`): past a few wrong tokens
an address is answered 429 for a while, without its tokens being looked at.
"""

from __future__ import annotations

import enum
import hashlib
import hmac
import ipaddress
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Protocol

from fcmaster.errors import ConfigError, FcmasterError

DEFAULT_PORT = 8080


class Role(enum.IntEnum):
    """What a caller may do; a higher role includes the lower ones."""

    VIEWER = 1
    OPERATOR = 2


@dataclass(slots=True, frozen=True)
class Principal:
    """An authenticated caller: the token's name (logged as the command's actor) and role."""

    name: str
    role: Role
    anonymous: bool = False  # let in without a token (loopback reads)

    def can(self, role: Role) -> bool:
        """Whether this caller holds ``role`` (or a higher one)."""
        return self.role >= role


ANONYMOUS = "anonymous"


class AuthError(FcmasterError):
    """The request cannot be let through; ``status`` is 401 or 403."""

    def __init__(
        self, status: int, reason: str, *, actor: str = "-", retry_after_s: float = 0.0
    ) -> None:
        self.status = status
        self.reason = reason
        self.actor = actor  # the token's name when it was recognised
        self.retry_after_s = retry_after_s  # 429: when the address may try again
        self.counted = False  # logged in aggregate by FailedAuthentications: not one by one
        super().__init__(reason)


class Throttle(Protocol):
    """Counts wrong tokens per address (``auth_failures.FailedAuthentications``)."""

    def check(self, host: str) -> None:
        """AuthError (429) while ``host`` may not try again."""

    def fail(self, host: str, error: AuthError) -> None:
        """``host`` presented a token that let it nowhere."""


@dataclass(slots=True, frozen=True)
class _Token:
    name: str
    role: Role
    digest: bytes


def _digest(secret: str) -> bytes:
    return hashlib.sha256(secret.encode("utf-8", "surrogatepass")).digest()


def is_loopback_host(host: str | None) -> bool:
    """Whether ``host`` (an address or a name, maybe with a port) means this machine."""
    if not host:
        return False
    name = split_host_port(host)[0].lower()
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def split_host_port(text: str) -> tuple[str, int | None]:
    """``"[::1]:8080"`` → ``("::1", 8080)``, ``"example"`` → ``("example", None)``."""
    text = text.strip()
    if text.startswith("["):
        host, _, rest = text[1:].partition("]")
        port = rest[1:] if rest.startswith(":") else ""
    elif text.count(":") == 1:
        host, _, port = text.partition(":")
    else:  # a bare IPv6 address, or no port at all
        host, port = text, ""
    return host, int(port) if port.isdigit() else None


def parse_listen(text: str) -> tuple[str, int]:
    """``"127.0.0.1:8080"``, ``"[::1]:8080"``, ``"0.0.0.0"`` → host and port (8080)."""
    stripped = text.strip()
    if stripped.startswith("["):
        raw = stripped.rpartition("]:")[2] if "]:" in stripped else None
    else:
        raw = stripped.partition(":")[2] if stripped.count(":") == 1 else None
    host, port = split_host_port(stripped)
    if not host or (raw is not None and not raw.isdigit()):
        raise ConfigError([("http.listen", f"{text!r} is not like 127.0.0.1:8080")])
    if port is not None and port > 65535:
        raise ConfigError([("http.listen", f"port {port} is beyond 65535")])
    return host, DEFAULT_PORT if port is None else port


def listen_problem(listen: str, *, has_tokens: bool) -> str:
    """Why the API may not listen at ``listen`` ("" when it may).

    The one rule of both ``fcmaster check`` and ``fcmaster run``.
    """
    try:
        host, _ = parse_listen(listen)
    except ConfigError as exc:
        return exc.problems[0][1]
    if not has_tokens and not is_loopback_host(host):
        return (
            f"{listen} is not a loopback address: with no http.tokens the API is "
            "read-only and served on loopback only; listen on 127.0.0.1 or add tokens"
        )
    return ""


class Authenticator:
    """Checks bearer tokens and the anonymous rules (see the module docstring)."""

    def __init__(
        self,
        tokens: Iterable[tuple[str, Role, str]],
        *,
        anonymous: bool,
        failures: Throttle | None = None,
    ) -> None:
        """Tokens as ``(name, role, secret)``; ``anonymous``: let loopback reads through.

        ``failures`` counts and throttles wrong tokens per client address (HTTP).
        """
        self._tokens = tuple(_Token(name, role, _digest(secret)) for name, role, secret in tokens)
        self.failures = failures
        # With no token at all nobody could read: the API is then read-only for loopback.
        self.anonymous = anonymous or not self._tokens

    @property
    def has_tokens(self) -> bool:
        """Whether any token is configured (else commands are impossible)."""
        return bool(self._tokens)

    def authenticate(
        self, authorization: str | None, *, client_host: str | None, host_header: str | None
    ) -> Principal:
        """The caller of one request; AuthError (401) when it cannot be let in at all.

        429 while its address is throttled for wrong tokens.
        """
        if authorization is not None:
            host = client_host or "?"
            if self.failures is not None:
                self.failures.check(host)
            try:
                scheme, _, secret = authorization.strip().partition(" ")
                if scheme.lower() != "bearer" or not secret.strip():
                    raise AuthError(401, "send the token as 'Authorization: Bearer <token>'")
                return self._match(secret.strip())
            except AuthError as error:
                if self.failures is not None:
                    self.failures.fail(host, error)
                raise
        if self.anonymous and is_loopback_host(client_host) and is_loopback_host(host_header):
            return Principal(ANONYMOUS, Role.VIEWER, anonymous=True)
        if self.anonymous:
            raise AuthError(401, "a token is needed from anywhere but this machine's loopback")
        raise AuthError(401, "a bearer token is needed (Authorization: Bearer <token>)")

    def _match(self, secret: str) -> Principal:
        given = _digest(secret)
        found: _Token | None = None
        for token in self._tokens:  # no early exit: every token costs the same time
            if hmac.compare_digest(given, token.digest) and found is None:
                found = token
        if found is None:
            raise AuthError(401, "the token is not recognised")
        return Principal(found.name, found.role)

    @staticmethod
    def require(principal: Principal, role: Role) -> None:
        """AuthError unless ``principal`` holds ``role``: 401 without a token, else 403."""
        if principal.can(role):
            return
        if principal.anonymous:
            raise AuthError(401, f"this needs an {role.name.lower()} token", actor=ANONYMOUS)
        raise AuthError(
            403,
            f"{principal.name} may only read: commands and parameter writes "
            f"need an {role.name.lower()} token",
            actor=principal.name,
        )
