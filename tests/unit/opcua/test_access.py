"""Who may connect and what they may do: users, request rules, certificates."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from asyncua import ua
from asyncua.common.utils import ServiceError
from asyncua.crypto.permission_rules import User, UserRole
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256, SecurityPolicyNone
from cryptography import x509
from structlog.testing import capture_logs

from fcmaster.errors import UsageError
from fcmaster.opcua import pki
from fcmaster.opcua.access import Channels, Gate, Rules, Users

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


def _listening(*policies: Any) -> Any:
    """A server's listener as :class:`Channels` sees it: one connection per channel policy."""
    clients = [
        SimpleNamespace(processor=SimpleNamespace(
            session=None, _connection=SimpleNamespace(security_policy=policy)
        ))
        for policy in policies
    ]  # fmt: skip
    given: list[Any] = []
    bserver = SimpleNamespace(clients=clients, set_policies=given.extend, given=given)
    return SimpleNamespace(
        bserver=bserver, iserver=SimpleNamespace(certificate=None, private_key=None)
    )


def test_a_session_lives_only_on_a_channel_offered() -> None:
    secure = SimpleNamespace(URI=SecurityPolicyBasic256Sha256.URI,
                             Mode=ua.MessageSecurityMode.SignAndEncrypt)  # fmt: skip
    plain = SimpleNamespace(URI=SecurityPolicyNone.URI, Mode=ua.MessageSecurityMode.None_)
    server = _listening(secure, plain)
    channels = Channels(server, ["Basic256Sha256:SignAndEncrypt"], Rules(anonymous=False))
    session = SimpleNamespace(name=("10.0.0.9", 50000))
    secure_one, none_one = (c.processor for c in server.bserver.clients)
    secure_one.session = session
    channels.check(session)  # type: ignore[arg-type]  # the shape check reads
    none_one.session = session  # the same session reattached to a None channel by its token
    with capture_logs() as logs, pytest.raises(ServiceError) as refused:
        channels.check(session)  # type: ignore[arg-type]
    assert refused.value.code == ua.StatusCodes.BadSecurityPolicyRejected
    assert [(e["event"], e["security"]) for e in logs] == [("opcua.session_refused", "None")]
    offered = Channels(server, ["None", "Basic256Sha256:SignAndEncrypt"], Rules(anonymous=False))
    offered.check(session)  # type: ignore[arg-type]


def test_a_none_channel_not_offered_serves_discovery_alone() -> None:
    server = _listening()
    rules = Rules(anonymous=True)
    channels = Channels(server, ["Basic256Sha256:SignAndEncrypt"], rules)
    channels.limit_none([ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt])
    secure, none = server.bserver.given
    assert secure.matches(SecurityPolicyBasic256Sha256.URI, ua.MessageSecurityMode.SignAndEncrypt)
    assert secure.permission_ruleset is rules
    assert none.matches(SecurityPolicyNone.URI, ua.MessageSecurityMode.None_)
    operator = User(role=UserRole.User, name="ops")
    # asyncua asks these rules about every request but the sessions' and discovery's own
    for kind in ("Read", "Browse", "Call", "CreateSubscription", "Publish"):
        assert none.create(None).permissions.check_validity(operator, request(kind), None) is False
    server.bserver.given.clear()
    Channels(server, ["None"], rules).limit_none([ua.SecurityPolicyType.NoSecurity])
    assert server.bserver.given == []  # None offered: asyncua's own policy, with the rules


def test_only_the_certificates_refused_last_are_kept(tmp_path: Path) -> None:
    refused = [f"certificate {n}".encode() for n in range(6)]
    for der in refused[:4]:
        pki.reject(tmp_path, der, keep=3)
    pki.reject(tmp_path, refused[1], keep=3)  # refused again: the newest now
    pki.reject(tmp_path, refused[4], keep=3)
    kept = {f.stem for f in (tmp_path / "rejected").glob("*.der")}
    assert kept == {pki.thumbprint(refused[n]) for n in (1, 3, 4)}
    flood = tmp_path / "flood"
    for n in range(pki.KEEP_REJECTED + 20):  # a client making a new certificate each time
        pki.reject(flood, f"flood {n}".encode())
    kept = {f.stem for f in (flood / "rejected").glob("*.der")}
    assert kept == {pki.thumbprint(f"flood {n}".encode()) for n in range(20, 120)}
