"""What the simulator needs of one protocol: a :class:`SimProtocol` in the vendor's package.

Each vendor's simulated drives live in ``fcmaster/sim/<vendor>/`` with a ``simulator.py``
holding its ``SIMULATOR``; the protocol's spec names it (``ProtocolSpec.simulator``) and
:mod:`fcmaster.sim.build` finds it there, so the line itself stays vendor-neutral.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from fcmaster.bus.plan import LinePlan
from fcmaster.sim.line import RequestFramer, SimDrive
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
    # Drive settings a bus's config implies (Mitsubishi: Pr.124 from its terminator).
    line_parameters: Callable[[LinePlan], dict[str, float]] | None = None
    # The drives time each reply themselves (Mitsubishi: the request's waiting time), so
    # the bus's response delay is not theirs.
    own_timing: bool = False
