"""Who may connect to the OPC UA server and what they may do (asyncua, locked down).

asyncua as it comes accepts every client certificate, lets any user name in, lets users
write, and does not tell a method who called it. Here:

- :class:`Gate` checks each client certificate against ``pki/trusted/`` and files an unknown
  one in ``pki/rejected/`` (BadCertificateUntrusted) for an operator to trust;
- :class:`Users` knows the ``http.tokens`` (user name = token name, password = token),
  compared in constant time, and anonymous sessions only when they are switched on;
- :class:`Rules` lets sessions browse, read and subscribe; calls only for named users (the
  daemon then decides by the user's role); writes for nobody, so every variable is read-only
  whatever its access level says;
- :class:`Channels` lets sessions live only on the secure channels of ``opcua.security``:
  asyncua starts every connection on SecurityPolicyNone and lets an OpenSecureChannel for
  None through whether None is offered or not, and such a channel has no permission check
  at all. Clients need a None channel to discover the endpoints (GetEndpoints and
  FindServers, as OPC UA allows), so it stays open for that, and for nothing else;
- :func:`track_callers` makes every session put its user in :data:`CALLER` while it runs a
  call request, so a method learns who called it. The method runs inside that request's own
  await chain (asyncua awaits a coroutine method directly), so the variable holds exactly
  that session's user; a method that finds none refuses.
"""

from __future__ import annotations

import datetime
import hmac
from contextvars import ContextVar
from pathlib import Path
from typing import Any

import structlog
from asyncua import Server, ua
from asyncua.common.utils import ServiceError
from asyncua.crypto.permission_rules import SimpleRoleRuleset, User, UserRole
from asyncua.crypto.security_policies import (
    SECURITY_POLICY_TYPE_MAP,
    SecurityPolicyFactory,
    SecurityPolicyNone,
)
from asyncua.server.internal_server import InternalServer
from asyncua.server.internal_session import InternalSession
from asyncua.server.user_managers import UserManager
from asyncua.ua.uaerrors import BadCertificateTimeInvalid, BadCertificateUntrusted
from cryptography import x509
from cryptography.hazmat.primitives.serialization import Encoding

from fcmaster.opcua import pki as pki_module
from fcmaster.opcua.limits import SessionQuota
from fcmaster.opcua.sessions import SessionBook, channels_of

__all__ = ["CALLER", "Channels", "Gate", "Rules", "Users", "track_callers"]

CALLER: ContextVar[User | None] = ContextVar("fcmaster_opcua_caller", default=None)
log = structlog.get_logger("fcmaster.opcua")

_READING = (
    "CreateSessionRequest", "CloseSessionRequest", "ActivateSessionRequest", "ReadRequest",
    "BrowseRequest", "BrowseNextRequest", "GetEndpointsRequest", "FindServersRequest",
    "TranslateBrowsePathsToNodeIdsRequest", "CreateSubscriptionRequest",
    "ModifySubscriptionRequest", "DeleteSubscriptionsRequest", "TransferSubscriptionsRequest",
    "CreateMonitoredItemsRequest", "ModifyMonitoredItemsRequest",
    "DeleteMonitoredItemsRequest", "PublishRequest", "RepublishRequest",
    "CloseSecureChannelRequest", "SetMonitoringModeRequest", "SetPublishingModeRequest",
    "RegisterNodesRequest", "UnregisterNodesRequest",
)  # fmt: skip


def _id(name: str) -> ua.NodeId:
    return ua.NodeId(getattr(ua.ObjectIds, f"{name}_Encoding_DefaultBinary"))


def _ids(names: tuple[str, ...]) -> set[ua.NodeId]:
    return {_id(n) for n in names}


# the request kinds a refusal names (what else is refused is named by its type id)
_NAMES = {_id(n): n for n in ("WriteRequest", "CallRequest", "HistoryUpdateRequest",
                               "AddNodesRequest", "DeleteNodesRequest", "ReadRequest")}  # fmt: skip


_OPENING = (
    "CreateSessionRequest", "ActivateSessionRequest", "CloseSessionRequest",
    "GetEndpointsRequest", "FindServersRequest", "CloseSecureChannelRequest",
)  # fmt: skip


class Rules(SimpleRoleRuleset):  # the type asyncua's set_security_policy asks for
    """Read and subscribe for every session, call for named users, write for nobody.

    A session is anonymous until it is activated: unless anonymous sessions are switched on,
    one may then only activate itself (or close), never read.
    """

    def __init__(self, *, anonymous: bool) -> None:
        # SimpleRoleRuleset's own table is not used: check_validity reads this one
        reading = _ids(_READING)
        self._allowed = {
            UserRole.Anonymous: reading if anonymous else _ids(_OPENING),
            UserRole.User: reading | _ids(("CallRequest",)),
        }

    def check_validity(self, user: User, action_type_id: ua.NodeId, body: Any) -> bool:
        """Whether ``user`` may make a request of this type (a refusal is logged with who)."""
        if action_type_id in self._allowed.get(user.role, set()):
            return True
        kind = _NAMES.get(action_type_id, str(action_type_id))
        log.warning("opcua.request_refused", actor=f"opcua:{user.name or 'anonymous'}",
                    request=kind)  # fmt: skip
        return False


class _DiscoveryOnly(SimpleRoleRuleset):
    """The rules of a None channel where None is not offered: nothing but discovery.

    asyncua asks the rules about every request but CreateSession, ActivateSession,
    CloseSession, GetEndpoints, FindServers and RegisterServer: what it asks about is refused
    (a session created elsewhere and reattached here by its token included). The sessions
    themselves are refused by :class:`Channels`.
    """

    def __init__(self) -> None:
        """No table: nothing is allowed (SimpleRoleRuleset's own is not used)."""

    def check_validity(self, user: User, action_type_id: ua.NodeId, body: Any) -> bool:
        """Never."""
        kind = _NAMES.get(action_type_id, str(action_type_id))
        log.warning("opcua.request_refused", actor=f"opcua:{user.name or 'anonymous'}",
                    request=kind, security="None")  # fmt: skip
        return False


class Channels:
    """The secure channels that may carry a session: those of ``opcua.security``."""

    def __init__(self, server: Server, security: list[str], rules: SimpleRoleRuleset) -> None:
        self.server = server
        self.security = frozenset(security)
        self._rules = rules

    def check(self, session: InternalSession) -> None:
        """Refuse ``session`` (BadSecurityPolicyRejected) on a channel not offered."""
        for security in channels_of(self.server, session):
            if security not in self.security:
                log.warning("opcua.session_refused", client=_client(session.name),
                            security=security)  # fmt: skip
                raise ServiceError(ua.StatusCodes.BadSecurityPolicyRejected)

    def limit_none(self, policies: list[ua.SecurityPolicyType]) -> None:
        """Give the None channels discovery-only rules (call once the server listens).

        asyncua picks a channel's policy among those it is given, else keeps the None it
        started with, which carries no rules: where None is not offered, a None policy with
        :class:`_DiscoveryOnly` rules is given besides the offered ones.
        """
        if "None" in self.security or self.server.bserver is None:
            return
        iserver = self.server.iserver

        def factory(policy: Any, mode: Any, rules: Any) -> Any:
            # asyncua's factory is untyped: its arguments are the ones Server itself passes
            return SecurityPolicyFactory(  # type: ignore[no-untyped-call]
                policy, mode, iserver.certificate, iserver.private_key, permission_ruleset=rules
            )

        offered = (SECURITY_POLICY_TYPE_MAP[kind] for kind in policies)
        factories = [factory(policy, mode, self._rules) for policy, mode, _ in offered]
        factories.append(
            factory(SecurityPolicyNone, ua.MessageSecurityMode.None_, _DiscoveryOnly())
        )
        self.server.bserver.set_policies(factories)


def _client(address: Any) -> str:
    return f"{address[0]}:{address[1]}" if isinstance(address, tuple) else str(address)


class Users(UserManager):
    """The users of ``http.tokens`` (and anonymous readers when switched on)."""

    def __init__(self, tokens: dict[str, str], *, anonymous: bool) -> None:
        self._tokens = {name: secret.encode() for name, secret in tokens.items()}
        self._anonymous = anonymous

    def get_user(
        self,
        iserver: InternalServer,
        username: str | None = None,
        password: str | bytes | None = None,
        certificate: Any = None,
    ) -> User | None:
        """The session's user, or None to refuse it (BadUserAccessDenied).

        ``certificate`` is the client application's (the secure channel's), not a user's:
        only user names and anonymous sessions are offered (X.509 user tokens are not).
        """
        if username is None and password is None:
            return User(role=UserRole.Anonymous) if self._anonymous else None
        if username is None or password is None:
            return None
        given = password.encode() if isinstance(password, str) else bytes(password)
        secret = self._tokens.get(username)
        # Compared even for an unknown name, so the time taken does not tell names apart.
        if hmac.compare_digest(given, secret or b"\0" * len(given)) and secret is not None:
            return User(role=UserRole.User, name=username)
        return None


class Gate:
    """The client certificate check: trusted while its file is in ``pki/trusted/``."""

    def __init__(self, pki: Path, rejected: Any = None) -> None:
        self.pki = pki
        self._rejected = rejected  # told each refused certificate's thumbprint

    async def __call__(self, certificate: x509.Certificate, app: ua.ApplicationDescription) -> None:
        """Refuse an untrusted or expired certificate (asyncua's CertificateValidatorMethod)."""
        der = certificate.public_bytes(Encoding.DER)
        if not pki_module.trusted(self.pki, der):
            pki_module.reject(self.pki, der)
            if self._rejected is not None:
                self._rejected(pki_module.thumbprint(der), app.ApplicationUri)
            raise BadCertificateUntrusted
        now = datetime.datetime.now(datetime.UTC)
        if not certificate.not_valid_before_utc <= now <= certificate.not_valid_after_utc:
            raise BadCertificateTimeInvalid


class _CallerSession(InternalSession):
    book: SessionBook | None = None
    channels: Channels | None = None
    replaces: InternalSession | None = None  # its connection's previous session
    application = ""  # the client's own name, from its CreateSession

    async def create_session(
        self, params: ua.CreateSessionParameters, sockname: tuple[str, int] | None = None
    ) -> ua.CreateSessionResult:
        previous, self.replaces = self.replaces, None
        if previous is not None and not previous.is_activated():
            # asyncua forgets it without closing it: it would stay registered for ever
            await previous.close_session()
        if self.channels is not None:
            self.channels.check(self)
        description = params.ClientDescription
        if description is not None and description.ApplicationName is not None:
            self.application = description.ApplicationName.Text or ""
        result: ua.CreateSessionResult = await super().create_session(params, sockname)
        return result

    def activate_session(
        self, params: ua.ActivateSessionParameters, peer_certificate: bytes | None
    ) -> ua.ActivateSessionResult:
        if self.channels is not None:  # again: a session may be reattached to another channel
            self.channels.check(self)
        result: ua.ActivateSessionResult = super().activate_session(params, peer_certificate)
        if self.book is not None:  # reached only once the user was let in
            self.book.activated(self, self.application)
        return result

    async def close_session(self, delete_subs: bool = True) -> None:
        if self.book is not None:
            self.book.closed(self)
        await super().close_session(delete_subs)

    async def call(self, params: list[ua.CallMethodRequest]) -> list[ua.CallMethodResult]:
        token = CALLER.set(self.user)
        try:
            results: list[ua.CallMethodResult] = await super().call(params)
            return results
        finally:
            CALLER.reset(token)


def track_callers(
    iserver: InternalServer,
    book: SessionBook | None = None,
    channels: Channels | None = None,
    quota: SessionQuota | None = None,
) -> None:
    """Make every session ``iserver`` creates name its user in :data:`CALLER` during calls.

    With ``book``, each session also says when it is activated and when it closes; with
    ``channels``, it is created and activated only on a channel offered; with ``quota``, a
    connection creates only so many.
    """

    def create_session(
        name: str, user: User | None = None, external: bool = False
    ) -> InternalSession:
        user = user or User(role=UserRole.Anonymous)
        previous = quota.admit(name) if quota is not None and external else None
        session = _CallerSession(
            iserver,
            iserver.aspace,
            iserver.subscription_service,
            name,
            user=user,
            external=external,
        )
        session.book = book
        session.channels = channels
        session.replaces = previous
        return session

    # asyncua has no hook for the sessions it makes: its factory method is replaced
    iserver.create_session = create_session  # type: ignore[method-assign]
