"""Waiting in integration tests: on the fleet's state through the hub, or on what signals nothing.

The fleet state publishes its changes through the hub, so a test waits on it with
:meth:`~fcmaster.hub.Hub.wait_for` (woken by each publication, no polling). The master's
counters and a simulated drive's insides publish nothing: :func:`wait_for` polls those.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from fcmaster.hub import Hub
from fcmaster.state import DriveState, FleetState


async def wait_for(condition: Callable[[], object], timeout_s: float = 10.0) -> None:
    """Poll ``condition`` every 20 ms until it holds; TimeoutError after ``timeout_s``."""
    async with asyncio.timeout(timeout_s):
        while not condition():  # noqa: ASYNC110 - nothing to wait on but the state itself
            await asyncio.sleep(0.02)


async def drive_where(
    hub: Hub,
    fleet: FleetState,
    bus: str,
    name: str,
    check: Callable[[DriveState], object],
    timeout_s: float = 15.0,
) -> DriveState:
    """Drive ``name``'s state once it satisfies ``check``, as the hub's publications tell."""

    def found() -> DriveState | None:
        state = fleet.get(bus, name)
        return state if state is not None and check(state) else None

    return await hub.wait_for(found, timeout_s=timeout_s)
