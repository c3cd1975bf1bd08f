"""Building a simulated line from settings; the line itself stays vendor-neutral.

A protocol's simulated drives are described by a :class:`SimProtocol` in its own sim
package (``fcmaster/sim/<vendor>/simulator.py``), named by the protocol's spec
(``ProtocolSpec.simulator``, a ``"module:attribute"`` string, because the protocol layer
may not import the simulator). :data:`SIM_PROTOCOLS` resolves every registered protocol's
once, here; the addresses a simulated drive may have are the spec's for the line's options.
"""

from __future__ import annotations

import importlib
import random
from collections.abc import Iterable, Mapping
from functools import partial
from typing import Final

from fcmaster.clock import Clock
from fcmaster.errors import UsageError
from fcmaster.protocol.registry import PROTOCOLS, spec_for
from fcmaster.protocol.spec import OptionPairs
from fcmaster.sim.adapter import LatencyAdapter
from fcmaster.sim.line import SimLine
from fcmaster.sim.settings import DriveSettings, LineSettings
from fcmaster.sim.simulator import DriveFactory, SimProtocol

__all__ = ["SIM_PROTOCOLS", "DriveFactory", "SimProtocol", "build_line", "simulated_keys"]


def _resolve(reference: str) -> SimProtocol:
    module, _, attribute = reference.partition(":")
    simulator = getattr(importlib.import_module(module), attribute)
    if not isinstance(simulator, SimProtocol):  # pragma: no cover - a spec naming the wrong thing
        raise TypeError(f"{reference} is not a SimProtocol")
    return simulator


SIM_PROTOCOLS: Final[Mapping[str, SimProtocol]] = {
    name: _resolve(spec.simulator) for name, spec in PROTOCOLS.items()
}


def simulated_keys(protocol: str, source: object) -> OptionPairs:
    """The line keys of ``protocol`` its simulated drives take, as ``source`` has them.

    Those marked ``LineKey.simulated``, as (key, value) pairs for ``LineSettings``; a key
    ``source`` lacks takes its default (``ProtocolSpec.options_of``).
    """
    spec = spec_for(protocol)
    simulated = {key.name for key in spec.line_keys if key.simulated}
    return tuple((name, value) for name, value in spec.option_pairs(source) if name in simulated)


def build_line(
    line: LineSettings,
    drives: Iterable[tuple[int, DriveSettings]],
    *,
    clock: Clock,
    rng: random.Random | None = None,
) -> SimLine:
    """A line of ``line.protocol`` drives, one per ``(address, settings)``, powered up now.

    ``rng`` defaults to ``random.Random(line.faults.seed)`` (seed 0 when the plan has none),
    so the same settings give the same faults. Raises UsageError for an unknown protocol,
    a bad or repeated address, or settings a drive cannot take.
    """
    protocol = SIM_PROTOCOLS.get(line.protocol)
    if protocol is None:
        known = ", ".join(SIM_PROTOCOLS)
        raise UsageError(f"no simulated drives for protocol {line.protocol!r} yet (have: {known})")
    drives = list(drives)
    addresses = [address for address, _ in drives]
    allowed = PROTOCOLS[line.protocol].addresses(line)
    bad = [a for a in addresses if a not in allowed]
    if bad:
        shown = ", ".join(str(a) for a in bad[:5]) + (
            f" and {len(bad) - 5} more" if bad[5:] else ""
        )
        raise UsageError(f"{line.protocol} addresses are {_span(allowed)}, not {shown}")
    repeated = sorted({a for a in addresses if addresses.count(a) > 1})
    if repeated and not line.duplicate_addresses:
        raise UsageError(f"addresses {repeated} appear more than once on line {line.name}")
    now = clock.now()
    latency_ms = line.adapter_latency_ms
    adapter = None if latency_ms is None else LatencyAdapter(latency_ms / 1000.0, epoch=now)
    return SimLine(
        drives=[protocol.new_drive(address, settings, line, now) for address, settings in drives],
        framer_factory=partial(protocol.framer_for, [settings for _, settings in drives]),
        baudrate=line.baudrate,
        char_bits=line.char_bits,
        clock=clock,
        faults=line.faults,
        drive_faults={a: s.faults for a, s in drives if s.faults is not None},
        rng=rng or random.Random(line.faults.seed or 0),
        adapter=adapter,
        parity=line.parity,
    )


def _span(addresses: range) -> str:
    return f"{addresses.start}-{addresses.stop - 1}"
