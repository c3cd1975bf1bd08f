"""Who may connect and what they may do: users, request rules, certificates."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from asyncua import ua
from asyncua.crypto.permission_rules import User, UserRole
from cryptography import x509
from structlog.testing import capture_logs

from fcmaster.errors import UsageError
from fcmaster.opcua import pki
from fcmaster.opcua.access import Gate, Rules, Users

TOKENS = {"scada": "viewer-token-0123456789", "ops": "operator-token-0123456789"}
SERVER: Any = None  # get_user does not look at the server


def request(name: str) -> ua.NodeId:
    return ua.NodeId(getattr(ua.ObjectIds, f"{name}Request_Encoding_DefaultBinary"))


def test_users_are_the_tokens_and_nobody_else() -> None:
    users = Users(TOKENS, anonymous=False)
    assert users.get_user(SERVER, "ops", "operator-token-0123456789") == User(
        role=UserRole.User, name="ops"
    )
    assert users.get_user(SERVER, "ops", b"operator-token-0123456789") is not None
    assert users.get_user(SERVER, "ops", "viewer-token-0123456789") is None  # another's token
    assert users.get_user(SERVER, "admin", "operator-token-0123456789") is None
    assert users.get_user(SERVER, "ops", "") is None
    assert users.get_user(SERVER, None, None) is None  # anonymous: off by default
    # the client application's certificate is not a user's: a name still needs its token
    assert users.get_user(SERVER, "ops", "wrong", certificate=b"der") is None


def test_anonymous_sessions_are_let_in_only_when_switched_on() -> None:
    assert Users(TOKENS, anonymous=True).get_user(SERVER, None, None) == User(
        role=UserRole.Anonymous
    )


@pytest.mark.parametrize("anonymous", [False, True])
def test_nobody_writes_users_call_anonymous_only_reads(anonymous: bool) -> None:
    rules = Rules(anonymous=anonymous)
    named, nobody = User(role=UserRole.User, name="ops"), User(role=UserRole.Anonymous)
    for kind in ("Read", "Browse", "CreateSubscription", "CreateMonitoredItems", "Publish"):
        assert rules.check_validity(named, request(kind), None)
        assert rules.check_validity(nobody, request(kind), None) is anonymous
    assert rules.check_validity(named, request("Call"), None)
    assert not rules.check_validity(nobody, request("Call"), None)
    for kind in ("Write", "AddNodes", "DeleteNodes", "HistoryUpdate"):
        for user in (named, nobody, User(role=UserRole.Admin)):
            with capture_logs() as logs:
                assert not rules.check_validity(user, request(kind), None)
            actor = f"opcua:{user.name or 'anonymous'}"
            assert logs == [{"event": "opcua.request_refused", "actor": actor,
                             "request": f"{kind}Request", "log_level": "warning"}]  # fmt: skip
    assert rules.check_validity(nobody, request("ActivateSession"), None)  # to become a user


def _client_certificate(folder: Path) -> x509.Certificate:
    cert_file, _ = pki.own_certificate(folder)
    return x509.load_der_x509_certificate(cert_file.read_bytes())


async def test_an_unknown_certificate_is_rejected_into_the_pki_until_trusted(
    tmp_path: Path,
) -> None:
    client = _client_certificate(tmp_path / "client")
    server = tmp_path / "server"
    pki.own_certificate(server)
    told: list[str] = []
    gate = Gate(server, lambda thumbprint, uri: told.append(thumbprint))
    app = ua.ApplicationDescription(ApplicationUri="urn:client")
    with pytest.raises(ua.uaerrors.BadCertificateUntrusted):
        await gate(client, app)
    listed = pki.certificates(server)
    (rejected,) = listed["rejected"]
    assert told == [rejected["thumbprint"]]
    assert listed["trusted"] == []
    assert len(listed["own"]) == 1
    assert pki.trust(server, rejected["thumbprint"].upper()).parent == server / "trusted"
    await gate(client, app)  # no restart: the trusted folder decides at each connection
    assert pki.certificates(server)["rejected"] == []
    with pytest.raises(UsageError, match="trusted already"):
        pki.trust(server, rejected["thumbprint"])
    with pytest.raises(UsageError, match="no rejected certificate has thumbprint abc"):
        pki.trust(server, "abc")


def test_the_own_certificate_is_made_once(tmp_path: Path) -> None:
    first = pki.own_certificate(tmp_path)
    der = first[0].read_bytes()
    assert pki.own_certificate(tmp_path) == first
    assert first[0].read_bytes() == der
    assert first[1].stat().st_mode & 0o077 == 0  # the key is the owner's only
    names = x509.load_der_x509_certificate(der).extensions.get_extension_for_class(
        x509.SubjectAlternativeName
    )
    assert pki.APPLICATION_URI in names.value.get_values_for_type(x509.UniformResourceIdentifier)
