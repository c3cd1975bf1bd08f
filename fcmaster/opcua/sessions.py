"""The server's live sessions, as the daemon shows them (``GET /api/v1/status``, dashboard).

A session is listed once activated (its user is known then) and leaves the list when it
closes (a CloseSession, or its timeout after its connection was lost). Each entry says who
(``user``, null for an anonymous session), from where (``client``: address and port), with
what (``application``: the client's own name for itself), how (``security``: policy and
mode as ``opcua.security`` writes them) and ``since`` when (wall seconds). The book calls
its ``changed`` callback on each change, which sends the whole list to the daemon: sessions
come and go a few times a day, never often enough to batch.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from asyncua import Server, ua

__all__ = ["SessionBook", "channels_of"]


class SessionBook:
    """The sessions of one server; ``changed`` is told the list whenever it changes."""

    def __init__(self, server: Server, changed: Callable[[list[dict[str, Any]]], None]) -> None:
        self._server = server
        self._changed = changed
        self._sessions: dict[int, dict[str, Any]] = {}  # by id(session)

    def listed(self) -> list[dict[str, Any]]:
        """The live sessions, oldest first."""
        return sorted(self._sessions.values(), key=lambda s: s["since"])

    def activated(self, session: Any, application: str) -> None:
        """``session`` was activated (again: its user may have changed, its start has not)."""
        before = self._sessions.get(id(session))
        address = session.name  # asyncua names a session by its peer's (host, port)
        client = f"{address[0]}:{address[1]}" if isinstance(address, tuple) else str(address)
        self._sessions[id(session)] = {
            "user": session.user.name if session.user is not None else None,
            "client": client,
            "application": application,
            "security": self._security(session),
            "since": time.time() if before is None else before["since"],
        }
        if self._sessions[id(session)] != before:
            self._changed(self.listed())

    def closed(self, session: Any) -> None:
        """``session`` closed."""
        if self._sessions.pop(id(session), None) is not None:
            self._changed(self.listed())

    def _security(self, session: Any) -> str:
        """The policy and mode of the connection that carries ``session``."""
        return next(iter(channels_of(self._server, session)), "unknown")


def channels_of(server: Server, session: Any) -> list[str]:
    """The security of each connection that carries ``session``, as ``opcua.security`` writes it.

    Usually one; two while a client reattaches its session to a new connection, none once
    its connection is lost.
    """
    # asyncua keeps the channel's policy on its connection, not on the session it serves
    found = []
    listening = server.bserver
    for protocol in listening.clients if listening is not None else ():
        processor = protocol.processor
        if processor is not None and processor.session is session:
            policy = processor._connection.security_policy
            name = policy.URI.rpartition("#")[2]
            if policy.Mode == ua.MessageSecurityMode.None_:
                found.append(name)
            else:
                found.append(f"{name}:{ua.MessageSecurityMode(policy.Mode).name}")
    return found
