"""Bearer tokens, roles and the loopback rules for anonymous reads."""

from __future__ import annotations

import pytest

from fcmaster.adapters.auth import (
    Authenticator,
    AuthError,
    Principal,
    Role,
    is_loopback_host,
    split_host_port,
)
from fcmaster.adapters.http import parse_listen
from fcmaster.errors import ConfigError

TOKENS = [("ops", Role.OPERATOR, "operator-secret-0001"), ("scada", Role.VIEWER, "viewer-0002")]
LOCAL = {"client_host": "127.0.0.1", "host_header": "127.0.0.1:8080"}


def test_a_token_names_its_holder_and_role() -> None:
    auth = Authenticator(TOKENS, anonymous=False)
    assert auth.authenticate("Bearer operator-secret-0001", **LOCAL) == Principal(
        "ops", Role.OPERATOR
    )
    assert auth.authenticate("bearer   viewer-0002 ", **LOCAL) == Principal("scada", Role.VIEWER)


@pytest.mark.parametrize(
    "header",
    [
        "Bearer operator-secret-000",
        "Bearer operator-secret-00011",
        "Basic b3BzOng=",
        "Bearer ",
        "operator-secret-0001",
    ],
)
def test_anything_but_an_exact_bearer_token_is_401(header: str) -> None:
    auth = Authenticator(TOKENS, anonymous=True)  # a wrong token never falls back to anonymous
    with pytest.raises(AuthError) as caught:
        auth.authenticate(header, **LOCAL)
    assert caught.value.status == 401


def test_operators_may_everything_viewers_only_read() -> None:
    operator, viewer = Principal("ops", Role.OPERATOR), Principal("scada", Role.VIEWER)
    Authenticator.require(operator, Role.OPERATOR)
    Authenticator.require(viewer, Role.VIEWER)
    with pytest.raises(AuthError) as caught:
        Authenticator.require(viewer, Role.OPERATOR)
    assert (caught.value.status, caught.value.actor) == (403, "scada")
    assert "operator" in caught.value.reason


def test_anonymous_reads_only_from_loopback_naming_a_loopback_host() -> None:
    auth = Authenticator(TOKENS, anonymous=True)
    principal = auth.authenticate(None, **LOCAL)
    assert (principal.role, principal.anonymous) == (Role.VIEWER, True)
    assert auth.authenticate(None, client_host="::1", host_header="[::1]:8080").anonymous
    assert auth.authenticate(None, client_host="127.0.0.1", host_header="localhost").anonymous
    for client, host in (
        ("192.168.1.20", "127.0.0.1:8080"),
        ("127.0.0.1", "evil.example"),
        ("127.0.0.1", None),
        (None, "127.0.0.1"),
    ):
        with pytest.raises(AuthError):
            auth.authenticate(None, client_host=client, host_header=host)
    with pytest.raises(AuthError) as caught:
        Authenticator.require(principal, Role.OPERATOR)
    assert caught.value.status == 401  # a token would help, so: not 403


def test_without_anonymous_reads_a_token_is_needed() -> None:
    with pytest.raises(AuthError):
        Authenticator(TOKENS, anonymous=False).authenticate(None, **LOCAL)


def test_without_any_token_loopback_reads_are_anonymous_and_nothing_else() -> None:
    auth = Authenticator([], anonymous=False)
    assert not auth.has_tokens
    assert auth.authenticate(None, **LOCAL).anonymous
    with pytest.raises(AuthError):
        auth.authenticate("Bearer anything-at-all", **LOCAL)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("127.0.0.1:8080", ("127.0.0.1", 8080)),
        ("[::1]:9000", ("::1", 9000)),
        ("localhost", ("localhost", None)),
        ("::1", ("::1", None)),
        ("h:x", ("h", None)),
    ],
)
def test_hosts_and_ports_split(text: str, expected: tuple[str, int | None]) -> None:
    assert split_host_port(text) == expected


def test_loopback_hosts() -> None:
    assert is_loopback_host("127.0.0.2:80")
    assert is_loopback_host("LOCALHOST:8080")
    assert not is_loopback_host("0.0.0.0:8080")
    assert not is_loopback_host("example.org")
    assert not is_loopback_host("")


def test_listen_addresses_default_to_port_8080_and_bad_ones_name_the_key() -> None:
    assert parse_listen("127.0.0.1:0") == ("127.0.0.1", 0)
    assert parse_listen("0.0.0.0") == ("0.0.0.0", 8080)
    assert parse_listen("[::1]:8081") == ("::1", 8081)
    for bad in ("127.0.0.1:", ":8080", "127.0.0.1:99999"):
        with pytest.raises(ConfigError) as caught:
            parse_listen(bad)
        assert caught.value.problems[0][0] == "http.listen"
