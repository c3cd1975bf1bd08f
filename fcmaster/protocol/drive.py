"""Vendor-neutral words for what the master wants a drive to do.

Every codec translates a :class:`ControlIntent` into its own wire form (the FC control word
and reference, Mitsubishi run-command and frequency writes, ENC run-control frames), so the
bus and everything above it speak only these terms.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


class Motion(enum.StrEnum):
    """What the motor should be doing."""

    STOP = "stop"  # ramp down and stay ready
    RUN = "run"
    COAST = "coast"  # output off, motor free-wheels
    QUICK_STOP = "quick_stop"  # ramp down on the quick-stop ramp
    JOG = "jog"


@dataclass(slots=True, frozen=True)
class ControlIntent:
    """The commanded state of one drive: motion, direction, reference and a reset pulse."""

    motion: Motion = Motion.STOP
    reverse: bool = False
    reference_pct: float = 0.0
    reset: bool = False
