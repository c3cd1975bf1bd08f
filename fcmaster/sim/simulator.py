"""What the simulator needs of one protocol: a :class:`SimProtocol` in the vendor's package.

Each vendor's simulated drives live in ``fcmaster/sim/<vendor>/`` with a ``simulator.py``
holding its ``SIMULATOR``; the protocol's spec names it (``ProtocolSpec.simulator``) and
:mod:`fcmaster.sim.build` finds it there, so the line itself stays vendor-neutral.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass

from fcmaster.bus.plan import LinePlan
from fcmaster.sim.line import RequestFramer, SimDrive
from fcmaster.sim.settings import DriveSettings, LineSettings

# address, settings, the line's settings, power-up time → a drive
DriveFactory = Callable[[int, DriveSettings, LineSettings, float], SimDrive]


@dataclass(slots=True, frozen=True, kw_only=True)
class ReplayRules:
    """How a replay answers a request its capture does not hold byte for byte.

    A master's requests carry more than their question: an FC telegram carries the control
    word and reference the master commands. The answer depends only on the question (which
    drive, which parameter), so a replay answers a request by what its question got in the
    capture, and a request for a drive's status alone from that drive's latest answer.
    """

    # Cuts any request of the protocol out of the master's bytes.
    framer: Callable[[], RequestFramer]
    # What a request's answer depends on (None: no request the rules know).
    question: Callable[[bytes], Hashable | None]
    # The drive a request or reply is for (None: none, or a broadcast).
    address: Callable[[bytes], int | None]
    # The answer to a request built from another answer of the same drive (its status
    # now); None where that answer cannot tell (a parameter never read in the capture).
    answer: Callable[[bytes, bytes], bytes | None]


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
    # How `fcmaster sim --replay` answers requests it has no byte-identical capture of
    # (None: it answers only those).
    replay: ReplayRules | None = None
