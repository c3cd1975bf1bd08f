"""A drive's parameter set over the daemon, and its drift from a saved set.

The set is read one parameter at a time as ordinary reads through ``gateway.execute``, the
path ``GET …/parameters/{param}`` takes, so each read queues behind the line's idle poll like
any other and no new bus traffic class appears. A viewer's reads also take their turns of the
line's viewer-read spacing (``pace``, :mod:`fcmaster.adapters.readlimit`) one by one, so a set
costs the poll no more than the same reads asked separately. Saved sets stay
with the client (the files ``fcmaster params backup`` writes, as JSON): the daemon keeps no
store of its own and needs no config key for one.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from contextlib import AbstractAsyncContextManager, nullcontext
from typing import Any

from fcmaster.adapters.gateway import Gateway
from fcmaster.adapters.readlimit import ReadsBusy
from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.errors import CommandError, UsageError
from fcmaster.protocol.codec import DriveError, ParameterValue
from fcmaster.protocol.parameter_set import (
    ParameterSet,
    compare,
    identity_mismatches,
    profile_for,
    read_set,
)


class ReadFailed(CommandError):
    """A read that ended neither done nor refused by the drive (offline, timeout, …)."""

    def __init__(self, parameter: str, result: CommandResult) -> None:
        super().__init__(f"{parameter}: {result.outcome.value}")
        self.parameter, self.result = parameter, result


Pace = Callable[[str], AbstractAsyncContextManager[None]]  # a line's name → its read turn


def _unpaced(line: str) -> AbstractAsyncContextManager[None]:
    return nullcontext()


async def read_drive_set(
    gateway: Gateway, name: str, *, actor: str, pace: Pace | None = None
) -> ParameterSet:
    """Drive ``name``'s set now; KeyError if there is no such drive, ReadFailed on silence.

    ``pace`` (viewers): each read waits for its turn on the drive's line; ReadsBusy when
    too many reads already wait there.
    """
    plan, state = gateway.drive_plan(name), gateway.fleet.find(name)
    if plan is None or state is None:
        raise KeyError(name)
    profile = profile_for(state.protocol, profile=plan.profile)  # modbus-rtu: the drive's
    turn = pace or _unpaced

    async def read(parameter: str) -> ParameterValue | DriveError:
        command = Command(action=Action.READ, parameter=parameter, actor=actor)
        async with turn(state.bus):
            result = await gateway.execute(name, command)
        if result.outcome is Outcome.DONE and result.value is not None:
            return result.value
        if result.outcome is Outcome.REFUSED and result.error is not None:
            return result.error
        raise ReadFailed(parameter, result)

    return await read_set(profile, plan.address, read)


def drift(name: str, saved: ParameterSet, now: ParameterSet) -> dict[str, Any]:
    """How drive ``name`` (``now``) differs from ``saved``, as the API answers it."""
    differences = compare(saved, now)
    return {
        "drive": name,
        "equal": not differences,
        "identity_mismatches": identity_mismatches(profile_for(now.protocol), saved, now),
        "differences": [
            {
                "parameter": d.parameter,
                "name": d.name,
                "saved": None if d.left is None else d.left.to_dict(),
                "drive": None if d.right is None else d.right.to_dict(),
            }
            for d in differences
        ],
    }


async def fleet_drift(
    gateway: Gateway, saved_sets: dict[str, Any], *, actor: str, pace: Pace | None = None
) -> list[dict[str, Any]]:
    """Each named drive against its saved set: a line's drives in turn, lines side by side.

    UsageError (before any read) if a set is malformed, names no drive, or is of another
    protocol than its drive. A drive that cannot be read gets its outcome and reason.
    """
    parsed: dict[str, ParameterSet] = {}
    problems = []
    for name, data in saved_sets.items():
        state = gateway.fleet.find(name)
        if state is None or gateway.drive_plan(name) is None:
            problems.append(f"{name}: no drive of that name")
            continue
        try:
            parsed[name] = ParameterSet.from_dict(data, source=f"the set for {name}")
        except UsageError as exc:
            problems.append(str(exc))
            continue
        if parsed[name].protocol != state.protocol:
            problems.append(f"{name}: a {parsed[name].protocol} set for a {state.protocol} drive")
    if problems:
        raise UsageError("; ".join(problems))

    async def one(name: str, saved: ParameterSet) -> dict[str, Any]:
        try:
            now = await read_drive_set(gateway, name, actor=actor, pace=pace)
        except ReadFailed as failed:
            return {"drive": name, "parameter": failed.parameter, **failed.result.to_json()}
        except ReadsBusy as exc:
            return {"drive": name, "outcome": "busy", "reason": f"{exc}: try again shortly"}
        return {"outcome": "done", **drift(name, saved, now)}

    async def line(names: list[str]) -> dict[str, dict[str, Any]]:
        return {name: await one(name, parsed[name]) for name in names}

    by_line: dict[str, list[str]] = {}
    for name in parsed:
        state = gateway.fleet.find(name)
        assert state is not None  # checked above
        by_line.setdefault(state.bus, []).append(name)
    done: dict[str, dict[str, Any]] = {}
    for part in await asyncio.gather(*(line(names) for names in by_line.values())):
        done.update(part)
    return [done[name] for name in parsed]  # in the body's order
