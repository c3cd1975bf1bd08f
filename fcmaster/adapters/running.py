"""The command tasks an adapter started, ended when it closes.

A command an adapter carries out runs in a task of its own, so a slow drive never holds up
the adapter's other clients. At shutdown each still running gets a grace to end with its
true outcome; what is left then is cancelled (its command still ends in the line, with
``cancelled``, and is audited there).
"""

from __future__ import annotations

import asyncio


async def end_within(running: set[asyncio.Task[None]], grace_s: float) -> None:
    """Give the tasks in ``running`` ``grace_s`` to end; cancel the rest and wait for them."""
    if running:
        await asyncio.wait(running, timeout=grace_s)
    late = list(running)
    for task in late:
        task.cancel()
    if late:
        await asyncio.wait(late)
