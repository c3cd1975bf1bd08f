"""Building a simulated line from settings: the one place that knows every vendor's parts.

A vendor adds its simulator by adding a :class:`SimProtocol` to :data:`SIM_PROTOCOLS`: the
framer that cuts its requests out of the byte stream and a factory for its drives. The
line itself stays vendor-neutral.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import partial
from typing import Final

from fcmaster.bus.plan import LinePlan
from fcmaster.clock import Clock
from fcmaster.errors import UsageError
from fcmaster.protocol.danfoss_fc.framer import FcFramer
from fcmaster.sim.adapter import LatencyAdapter
from fcmaster.sim.danfoss_fc.drive import FcSimDrive
from fcmaster.sim.enc.drive import EncRequestFramer, EncSimDrive
from fcmaster.sim.line import RequestFramer, SimDrive, SimLine
from fcmaster.sim.mitsubishi import MitsubishiSimDrive, line_parameters, line_receiver
from fcmaster.sim.settings import DriveSettings, LineSettings

# address, settings, the line's settings, power-up time → a drive
DriveFactory = Callable[[int, DriveSettings, LineSettings, float], SimDrive]


@dataclass(slots=True, frozen=True)
class SimProtocol:
    """What the simulator needs of one protocol."""

    # The framer that cuts requests out of the bytes, for a line of drives with these
    # settings (they matter where the request format is a drive setting: Mitsubishi's
    # Pr.123 and Pr.124).
    framer_for: Callable[[list[DriveSettings]], RequestFramer]
    new_drive: DriveFactory
    addresses: range  # addresses a drive may have
    # Drive settings a bus's config implies (Mitsubishi: Pr.124 from its terminator).
    line_parameters: Callable[[LinePlan], dict[str, float]] | None = None
    # The drives time each reply themselves (Mitsubishi: the request's waiting time), so
    # the bus's response delay is not theirs.
    own_timing: bool = False


def _fc_drive(address: int, settings: DriveSettings, line: LineSettings, now: float) -> SimDrive:
    return FcSimDrive(address, settings, now=now, line=line)


def _mitsubishi_drive(
    address: int, settings: DriveSettings, line: LineSettings, now: float
) -> SimDrive:
    return MitsubishiSimDrive(address, settings, now=now, line=line)


def _enc_drive(address: int, settings: DriveSettings, line: LineSettings, now: float) -> SimDrive:
    return EncSimDrive(address, settings, now=now, line=line)


SIM_PROTOCOLS: Final[dict[str, SimProtocol]] = {
    "danfoss-fc": SimProtocol(lambda _: FcFramer(), _fc_drive, range(1, 127)),
    # 0 and 127 (broadcast) cannot name one drive; F2.15 allows them, the master does not
    "enc": SimProtocol(lambda _: EncRequestFramer(), _enc_drive, range(1, 127)),
    # stations 0-31; the link has no broadcast, so 0 is a drive like the others
    "mitsubishi": SimProtocol(
        line_receiver,
        _mitsubishi_drive,
        range(0, 32),
        line_parameters=line_parameters,
        own_timing=True,
    ),
}


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
    bad = [a for a in addresses if a not in protocol.addresses]
    if bad:
        raise UsageError(f"{line.protocol} addresses are {_span(protocol.addresses)}, not {bad}")
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
