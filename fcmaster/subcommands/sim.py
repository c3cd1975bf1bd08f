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
from functools import partial
from pathlib import Path
from typing import Final, TextIO

from fcmaster.clock import Clock, MonotonicClock
from fcmaster.config import load
from fcmaster.config_values import baudrate_problem
from fcmaster.errors import UsageError
from fcmaster.protocol import pcapng
from fcmaster.protocol.registry import spec_for
from fcmaster.sim import DriveSettings, LineSettings, PtyServer, build_line, parse_faults
from fcmaster.sim.build import simulated_keys
from fcmaster.sim.line import SimLine
from fcmaster.sim.replay import replay_lines, replay_sim_line
from fcmaster.sim.service import sim_settings

SIM_MAX_LEAD_S: Final = 0.001


@dataclass(slots=True, frozen=True)
class SimBus:
    """One simulated line to serve: its settings, its drives, and where to link its pty."""

    settings: LineSettings
    drives: Sequence[tuple[int, DriveSettings]]
    link: str | None = None


async def run(args: argparse.Namespace) -> int:
    """Serve the buses of ``--config``, a capture's (``--replay``), or the one line described."""
    if args.replay is not None:
        if args.config is not None:
            raise UsageError("--replay serves the lines of a capture; leave out --config")
        return await replay(args.replay, link=args.link)
    if args.config is not None:
        return await serve(config_buses(args.config, only=args.bus))
    if args.bus:
        raise UsageError("--bus selects buses of a --config file; give --config too")
    delay_ms = args.response_delay_ms
    spec = spec_for(args.protocol)
    factory = spec.factory  # as the drives leave the factory, like every other tool's default
    if args.baudrate is not None and args.baudrate not in spec.baudrates:
        raise UsageError(f"--baudrate {baudrate_problem(spec, args.baudrate)}")
    line = LineSettings(
        name=args.name,
        protocol=args.protocol,
        baudrate=args.baudrate or factory.baudrate,
        parity=args.parity or factory.parity,
        stopbits=args.stopbits or factory.stopbits,
        faults=parse_faults(args.faults),
        protocol_options=simulated_keys(args.protocol, args),  # the options the drives take
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
    names = [bus.settings.name for bus in buses]
    if len(set(names)) != len(names):
        raise UsageError(f"bus names must differ: {names}")
    lines = [
        (bus.settings.name, build_line(bus.settings, bus.drives, clock=clock), bus.link)
        for bus in buses
    ]
    return await _serve_lines(lines, clock=clock, out=out, stop=stop)


async def replay(
    path: Path,
    *,
    link: str | None = None,
    clock: Clock | None = None,
    out: TextIO | None = None,
    stop: asyncio.Event | None = None,
) -> int:
    """Serve the drives' side of the capture at ``path``; print each request it answers."""
    clock = clock or MonotonicClock(max_lead_s=SIM_MAX_LEAD_S)
    out = out or sys.stdout
    try:
        capture = pcapng.decode(await asyncio.to_thread(path.read_bytes))
    except OSError as exc:
        raise UsageError(f"cannot read {path}: {exc.strerror or exc}") from exc
    except pcapng.PcapngError as exc:
        raise UsageError(f"{path}: {exc}") from exc
    captured = replay_lines(capture)
    if link is not None and len(captured) > 1:
        raise UsageError(f"{path} holds {len(captured)} lines: --link needs a capture of one")
    lines = []
    for line in captured:
        served = partial(_print_served, line.name, out)
        sim_line = replay_sim_line(line, clock=clock, served=served)
        lines.append((line.name, sim_line, link))
    return await _serve_lines(lines, clock=clock, out=out, stop=stop)


def _print_served(name: str, out: TextIO, request: bytes, reply: bytes | None) -> None:
    answer = "(no answer)" if reply is None else reply.hex(" ")
    print(f"{name} {request.hex(' ')} -> {answer}", file=out, flush=True)


async def _serve_lines(
    lines: Sequence[tuple[str, SimLine, str | None]],
    *,
    clock: Clock,
    out: TextIO | None,
    stop: asyncio.Event | None,
) -> int:
    out = out or sys.stdout
    for name, _, link in lines:
        if link is not None and not Path(link).parent.is_dir():  # the user's, not the pty's
            raise UsageError(f"{name}: cannot link {link}: {Path(link).parent} is no directory")
    loop = asyncio.get_running_loop()
    handled: list[signal.Signals] = []
    if stop is None:
        stop = asyncio.Event()
        for signum in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(signum, stop.set)
            handled.append(signum)
    try:
        async with contextlib.AsyncExitStack() as stack:
            for name, line, link in lines:
                server = PtyServer(line, clock=clock, link=link)
                await stack.enter_async_context(server)
                print(f"{name} {server.device}", file=out, flush=True)
            await stop.wait()
    finally:
        for signum in handled:
            loop.remove_signal_handler(signum)
    return 0
