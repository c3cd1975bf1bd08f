"""Idle polls, encoded once: the same request bytes go out again and again.

A line polls every drive through the same few exchanges (one per monitor slot, and for a
drive under bus control, the same control word until its intent changes), so building the
telegram each time (its fields, its checksum, the Exchange around it) is work thrown away.
:class:`PollCache` keeps the exchange each (address, intent, read) was given the first
time; an :class:`~fcmaster.protocol.codec.Exchange` is frozen, so handing the same one out
again is safe. A request the codec refuses (a bad index, say) raises as before and is not
kept. The cache forgets everything when it grows past :attr:`PollCache.LIMIT` entries (a
reference that changes with every poll would otherwise grow it without end).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

from fcmaster.protocol.codec import Exchange, ParameterKey
from fcmaster.protocol.drive import ControlIntent

PollKey = tuple[int, ControlIntent | None, ParameterKey | None]


class PollCache:
    """The exchange of each idle poll, built by ``build`` the first time it is asked for."""

    __slots__ = ("_build", "_exchanges")

    LIMIT: ClassVar[int] = 4096

    def __init__(
        self, build: Callable[[int, ControlIntent | None, ParameterKey | None], Exchange]
    ) -> None:
        self._build = build
        self._exchanges: dict[PollKey, Exchange] = {}

    def get(
        self, address: int, intent: ControlIntent | None, read: ParameterKey | None
    ) -> Exchange:
        """The poll of ``address`` carrying ``intent`` and reading ``read``."""
        key = (address, intent, read)
        exchange = self._exchanges.get(key)
        if exchange is None:
            exchange = self._build(address, intent, read)
            if len(self._exchanges) >= self.LIMIT:
                self._exchanges.clear()
            self._exchanges[key] = exchange
        return exchange
