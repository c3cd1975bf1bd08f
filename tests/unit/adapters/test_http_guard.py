from typing import Any, cast

from fcmaster.adapters.http_guard import ConnectionGuard, GuardedProtocol
from tests.fakes import FakeClock


class Conn:
    def __init__(self, name: str) -> None:
        self.name = name
        self.closed = False
        self.reserved = False

    def close_now(self) -> None:
        self.closed = True


def _admit(guard: ConnectionGuard, name: str, host: str) -> tuple[bool, Any]:
    conn = Conn(name)
    return guard.admit(cast(GuardedProtocol, conn), host), conn


def test_a_full_server_closes_the_oldest_idle_connection_of_the_biggest_holder() -> None:
    guard = ConnectionGuard(clock=FakeClock(), max_connections=3, reserve=1)
    _, a = _admit(guard, "a", "10.0.0.1")
    _, b = _admit(guard, "b", "10.0.0.2")
    _, c = _admit(guard, "c", "10.0.0.2")
    ok, _ = _admit(guard, "d", "10.0.0.9")
    assert ok
    assert (a.closed, b.closed, c.closed) == (False, True, False)  # .2 held the most
    assert guard.per_host == {"10.0.0.1": 1, "10.0.0.2": 1, "10.0.0.9": 1}
    # .2 just lost an idle connection: it cannot push another one out while full
    assert _admit(guard, "e", "10.0.0.2")[0] is False
    assert guard.refused == 1
    # a newcomer can
    assert _admit(guard, "f", "10.0.0.7")[0] is True
    assert a.closed


def test_when_every_connection_is_busy_the_reserve_takes_one_more_for_stops() -> None:
    guard = ConnectionGuard(clock=FakeClock(), max_connections=2, reserve=1)
    conns = [_admit(guard, n, "10.0.0.1")[1] for n in "ab"]
    for conn in conns:
        guard.busy(cast(GuardedProtocol, conn))
    ok, spare = _admit(guard, "c", "10.0.0.2")
    assert ok
    assert spare.reserved is True
    # an idle reserve connection makes room like any idle one, and its heir is one too
    ok, heir = _admit(guard, "d", "10.0.0.3")
    assert ok
    assert (spare.closed, heir.reserved) == (True, True)
    guard.busy(cast(GuardedProtocol, heir))
    assert _admit(guard, "x", "10.0.0.4")[0] is False  # all busy, the reserve taken
    guard.gone(cast(GuardedProtocol, conns[0]))
    guard.gone(cast(GuardedProtocol, heir))
    ok, plain = _admit(guard, "e", "10.0.0.3")
    assert ok
    assert plain.reserved is False


def test_one_address_makes_room_from_its_own_connections() -> None:
    guard = ConnectionGuard(clock=FakeClock(), per_client=2)
    first = _admit(guard, "a", "10.0.0.1")[1]
    _admit(guard, "b", "10.0.0.1")
    assert _admit(guard, "c", "10.0.0.1")[0] is True
    assert first.closed
    busy = [c for c in guard.open]
    for conn in busy:
        guard.busy(conn)
    assert _admit(guard, "d", "10.0.0.1")[0] is False  # both busy: nothing to give up


def test_the_penalty_for_an_idle_connection_ends_a_head_timeout_later_on_the_clock() -> None:
    clock = FakeClock(start=0.0)
    guard = ConnectionGuard(clock=clock, max_connections=3, reserve=1, head_timeout_s=5.0)
    for name, host in (("a", "10.0.0.1"), ("b", "10.0.0.2"), ("c", "10.0.0.2")):
        _admit(guard, name, host)
    assert _admit(guard, "d", "10.0.0.9")[0] is True  # .2 loses an idle one: penalised
    clock.time = 4.9
    assert _admit(guard, "e", "10.0.0.2")[0] is False
    clock.time = 5.0
    assert _admit(guard, "f", "10.0.0.2")[0] is True  # its penalty is over: it may make room
