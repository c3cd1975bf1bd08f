"""How many connections and sessions a client may hold before it has logged in.

asyncua accepts up to ``max_connections`` (1000) connections and closes one that has not
activated a session only after ``max_pending_activation_seconds`` (30 s): a thousand idle
sockets from one address kept every SCADA client out, again and again. Each CreateSession
on a connection also makes a session (and a watchdog task) that stays until the connection
closes, however many came before. Here:

- a connection has :data:`HANDSHAKE_S` to activate a session (asyncua's own watchdog);
- one address holds at most :data:`PENDING_PER_ADDRESS` connections without an activated
  session: a new one closes that address's oldest, so an attacker's idle sockets make way
  for a client that is still logging in, and connections already logged in are never
  touched (:class:`Crowd`);
- a connection creates at most :data:`SESSIONS_PER_CONNECTION` sessions
  (BadTooManySessions), and a session it created but never activated is closed when it
  creates the next (:class:`SessionQuota`).
"""

from __future__ import annotations

import weakref
from typing import Any, Final

import structlog
from asyncua import Server, ua
from asyncua.common.utils import ServiceError

__all__ = [
    "HANDSHAKE_S",
    "PENDING_PER_ADDRESS",
    "SESSIONS_PER_CONNECTION",
    "Crowd",
    "SessionQuota",
    "apply",
]

HANDSHAKE_S: Final = 10.0  # a client connects, opens its channel and logs in well within this
PENDING_PER_ADDRESS: Final = 16  # a SCADA host opens a few at once (discovery, then a session)
SESSIONS_PER_CONNECTION: Final = 8  # a client retrying its login on one channel

log = structlog.get_logger("fcmaster.opcua")


def _logged_in(protocol: Any) -> bool:
    processor = protocol.processor
    return bool(processor is not None and processor.session is not None
                and processor.session.is_activated())  # fmt: skip


def _address(protocol: Any) -> Any:
    peer = protocol.peer_name
    return peer[0] if isinstance(peer, tuple) else peer


class Crowd(list[Any]):
    """The server's connections (asyncua's ``BinaryServer.clients``), in order of arrival.

    asyncua appends each connection it accepts: past :data:`PENDING_PER_ADDRESS` not yet
    logged in from one address, that address's oldest such connection is closed.
    """

    def __init__(self, connections: list[Any], per_address: int = PENDING_PER_ADDRESS) -> None:
        super().__init__(connections)
        self.per_address = per_address

    def append(self, protocol: Any) -> None:
        """Admit ``protocol``, making room among its address's connections not logged in."""
        address = _address(protocol)
        pending = [p for p in self if _address(p) == address and not _logged_in(p)]
        for oldest in pending[: max(0, len(pending) - self.per_address + 1)]:
            log.warning("opcua.connection_closed", client=address, reason="too many pending")
            if oldest.transport is not None:
                oldest.transport.close()
        super().append(protocol)


class SessionQuota:
    """How many sessions each connection of ``server`` has created."""

    def __init__(self, server: Server, per_connection: int = SESSIONS_PER_CONNECTION) -> None:
        self.server = server
        self.per_connection = per_connection
        self._created: weakref.WeakKeyDictionary[Any, int] = weakref.WeakKeyDictionary()

    def admit(self, name: Any) -> Any:
        """Count a new session of the connection ``name`` (its peer); return its previous one.

        Raises ServiceError (BadTooManySessions) past the quota. None when the connection
        had no session yet, or is not a client's.
        """
        listening = self.server.bserver
        for protocol in listening.clients if listening is not None else ():
            processor = protocol.processor
            if protocol.peer_name == name and processor is not None:
                created = self._created.get(processor, 0)
                if created >= self.per_connection:
                    log.warning("opcua.session_refused", client=str(name),
                                reason="too many sessions")  # fmt: skip
                    raise ServiceError(ua.StatusCodes.BadTooManySessions)
                self._created[processor] = created + 1
                return processor.session
        return None


def apply(server: Server) -> None:
    """Put the limits on ``server``: the handshake's before it starts, the crowd's after."""
    server.iserver.max_pending_activation_seconds = HANDSHAKE_S
    if server.bserver is not None and not isinstance(server.bserver.clients, Crowd):
        server.bserver.clients = Crowd(server.bserver.clients)
