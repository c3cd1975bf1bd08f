"""`fcmaster sim`: serve simulated drives on pseudo-terminals until SIGINT or SIGTERM.

:func:`serve` takes any number of buses, each a :class:`SimBus` (line settings, a list of
``(address, drive settings)`` and an optional link), so ``fcmaster sim --config FILE`` only
has to turn the config's buses into that list.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final, TextIO

from fcmaster.clock import Clock, MonotonicClock
from fcmaster.config import load
from fcmaster.errors import UsageError
from fcmaster.sim import DriveSettings, LineSettings, PtyServer, build_line, parse_faults
from fcmaster.sim.service import sim_settings

SIM_MAX_LEAD_S: Final = 0.001


@dataclass(slots=True, frozen=True)
class SimBus:
    """One simulated line to serve: its settings, its drives, and where to link its pty."""

    settings: LineSettings
    drives: Sequence[tuple[int, DriveSettings]]
    link: str | None = None


async def run(args: argparse.Namespace) -> int:
    """Serve the buses of ``--config``, or the one line the other options describe."""
    if args.config is not None:
        return await serve(config_buses(args.config, only=args.bus))
    if args.bus:
        raise UsageError("--bus selects buses of a --config file; give --config too")
    delay_ms = args.response_delay_ms
    line = LineSettings(
        name=args.name,
        protocol=args.protocol,
        baudrate=args.baudrate,
        parity=args.parity,
        stopbits=args.stopbits,
        faults=parse_faults(args.faults),
        address_encoding=args.address_encoding,
        response_encoding=args.response_encoding,
        fault_encoding=args.fault_encoding,
        adapter_latency_ms=args.adapter_latency_ms,
        duplicate_addresses=args.duplicate_addresses,
    )
    drive = DriveSettings(response_delay_s=None if delay_ms is None else delay_ms / 1000.0)
    return await serve([SimBus(line, [(address, drive) for address in args.addresses], args.link)])


def config_buses(path: Path, *, only: Sequence[str] | None = None) -> list[SimBus]:
    """Every bus of the config at ``path`` whose port is a device path, linked to its pty.

    ``sim://`` buses are left out: the daemon serves those in-process itself. ``only``
    names the buses to serve (default: all of them), so one line can be served by a
    process of its own and taken away (an unplugged adapter) while the others stay.
    """
    config = load(path, buses_only=True)  # the daemon's secrets are no business of ours
    if only:
        unknown = sorted(set(only) - {plan.name for plan in config.lines})
        if unknown:
            raise UsageError(f"{path} has no bus called {', '.join(unknown)}")
    buses = []
    for plan in config.lines:
        if plan.port.startswith("sim://") or (only and plan.name not in only):
            continue
        if "://" in plan.port:
            raise UsageError(f"bus {plan.name}: {plan.port} is not a device path to link a pty at")
        model = next(b for b in config.model.buses if b.name == plan.name)
        settings, drives = sim_settings(plan, model.simulation or {})
        buses.append(SimBus(settings, drives, link=plan.port))
    if not buses:
        chosen = f"of {', '.join(only)} " if only else ""
        raise UsageError(f"{path} has no bus {chosen}with a device path to simulate")
    return buses


async def serve(
    buses: Sequence[SimBus],
    *,
    clock: Clock | None = None,
    out: TextIO | None = None,
    stop: asyncio.Event | None = None,
) -> int:
    """Serve every bus on its own pty; print ``BUS PATH`` for each; run until ``stop``.

    ``stop`` defaults to an event set by SIGINT or SIGTERM. Links are removed on the way
    out, however it ends.
    """
    # A simulator's job is to keep time, so it may spin up to 1 ms to answer on time.
    clock = clock or MonotonicClock(max_lead_s=SIM_MAX_LEAD_S)
    out = out or sys.stdout
    names = [bus.settings.name for bus in buses]
    if len(set(names)) != len(names):
        raise UsageError(f"bus names must differ: {names}")
    loop = asyncio.get_running_loop()
    handled: list[signal.Signals] = []
    if stop is None:
        stop = asyncio.Event()
        for signum in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(signum, stop.set)
            handled.append(signum)
    try:
        async with contextlib.AsyncExitStack() as stack:
            for bus in buses:
                line = build_line(bus.settings, bus.drives, clock=clock)
                server = PtyServer(line, clock=clock, link=bus.link)
                await stack.enter_async_context(server)
                print(f"{bus.settings.name} {server.device}", file=out, flush=True)
            await stop.wait()
    finally:
        for signum in handled:
            loop.remove_signal_handler(signum)
    return 0
