"""Vendor-neutral words for what the master wants a drive to do.

Every codec translates a :class:`ControlIntent` into its own wire form (the FC control word
and reference, Mitsubishi run-command and frequency writes, ENC run-control frames), so the
bus and everything above it speak only these terms.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeVar

if TYPE_CHECKING:
    from fractions import Fraction


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


# A reference in % and an output in Hz are the same quantity, scaled by the drive's nominal
# frequency (the config's ``nominal_frequency_hz``: what 100 % means). Replies carry Hz; a
# percentage exists only where a protocol or a caller speaks it. These two are the one place
# the scaling is written; they keep exact arithmetic exact (a Fraction in, a Fraction out).
DEFAULT_NOMINAL_HZ = 50.0  # when a drive's nominal frequency is not configured

Number = TypeVar("Number", float, "Fraction")


def pct_to_hz(pct: Number, nominal_hz: Number) -> Number:
    """The frequency ``pct`` % of ``nominal_hz`` is."""
    return pct * nominal_hz / 100


def hz_to_pct(hz: Number, nominal_hz: Number) -> Number:
    """The share of ``nominal_hz`` (in %) that ``hz`` is."""
    return hz / nominal_hz * 100
