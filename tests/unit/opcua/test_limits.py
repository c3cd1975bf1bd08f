"""How many connections an address holds before logging in, and sessions a connection makes."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from fcmaster.opcua.limits import Crowd


def _connection(address: str, *, logged_in: bool = False) -> Any:
    session = SimpleNamespace(is_activated=lambda: logged_in)
    closed: list[bool] = []
    return SimpleNamespace(
        peer_name=(address, 40000),
        processor=SimpleNamespace(session=session),
        transport=SimpleNamespace(close=lambda: closed.append(True)),
        closed=closed,
    )


def test_an_address_past_its_pending_connections_loses_its_oldest_not_logged_in() -> None:
    crowd = Crowd([], per_address=3)
    working = _connection("10.0.0.5", logged_in=True)
    crowd.append(working)
    idle = [_connection("10.0.0.5") for _ in range(3)]
    for connection in idle:
        crowd.append(connection)
    other = _connection("10.0.0.6")
    crowd.append(other)
    assert not any(c.closed for c in (*idle, working, other))  # at the cap, none closed yet
    crowd.append(_connection("10.0.0.5"))  # one past the cap: the oldest idle makes way
    assert [bool(c.closed) for c in idle] == [True, False, False]
    assert not working.closed  # logged in: never touched
    assert not other.closed  # another address: never touched
