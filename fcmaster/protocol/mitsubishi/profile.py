"""Status and run-command bits, and frequency scaling (protocols/mitsubishi.md §8-§10).

Only the direction bits are fixed. The others report or drive whatever the output and input
terminal functions are set to (Pr.190-Pr.196, Pr.178-Pr.189); the names here are the
factory assignments, and the normalised status relies on them only where nothing fixed
exists (at reference, fault in H7A, overload warning).
"""

from __future__ import annotations

import enum
from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.codec import DriveStatus
from fcmaster.protocol.drive import ControlIntent, Motion


class StatusBits(enum.IntFlag):
    """Inverter status monitor H7A (8 bits) and H79 (16 bits), §10.1."""

    RUN = 1 << 0  # inverter running (Pr.190 RUN)*
    FORWARD = 1 << 1  # forward running, fixed
    REVERSE = 1 << 2  # reverse running, fixed
    SU = 1 << 3  # up to frequency*
    OL = 1 << 4  # overload: stall prevention active*
    IPF = 1 << 5  # instantaneous power failure / undervoltage* (reads 0 on E700/D700)
    FU = 1 << 6  # output frequency detection*
    ABC1 = 1 << 7  # fault output (ALM)*
    ABC2 = 1 << 8  # H79 only (A700/F700)*
    FAULT = 1 << 15  # H79 only: fault occurrence, fixed


class RunCommand(enum.IntFlag):
    """Run command HFA (8 bits) and HF9 (16 bits), §10.2; factory input assignments."""

    AU = 1 << 0  # current input selection* (A700/F700; not used on E700/D700)
    STF = 1 << 1  # forward rotation, fixed
    STR = 1 << 2  # reverse rotation, fixed
    RL = 1 << 3  # low speed*
    RM = 1 << 4  # middle speed*
    RH = 1 << 5  # high speed*
    RT = 1 << 6  # second function* (A700/F700)
    MRS = 1 << 7  # output stop*


class OperationMode(enum.IntEnum):
    """H7B/HFB operation mode data on the 700/800 series (§9; other families differ)."""

    NETWORK = 0x0000
    EXTERNAL = 0x0001
    PU = 0x0002


FREQUENCY_STEP_HZ: Final = 0.01  # H6D/H6E/H6F and HED/HEE are in 0.01 Hz (§9)
MAX_FREQUENCY_RAW: Final = 0xFFFF  # four digits; the drive's own limit (Pr.1/Pr.18) is lower


def run_command(intent: ControlIntent) -> int:
    """The HFA data that commands ``intent``'s motion and direction.

    Stop and quick stop both clear STF and STR: the drive decelerates on its ramp (Pr.8);
    the link has no quick-stop ramp. Coast sets MRS (output stop) with STF and STR clear,
    so a drive whose terminal 7 is assigned to something else still stops on its ramp.
    Jog has no bit in HFA (only some models have one in HF9): UsageError.
    """
    motion = intent.motion
    if motion is Motion.RUN:
        return int(RunCommand.STR if intent.reverse else RunCommand.STF)
    if motion is Motion.COAST:
        return int(RunCommand.MRS)
    if motion in (Motion.STOP, Motion.QUICK_STOP):
        return 0
    raise UsageError(f"{motion} has no run-command bit on the Mitsubishi computer link")


def frequency_raw(frequency_hz: float) -> int:
    """The 4-digit HED/HEE data for ``frequency_hz``; UsageError if it cannot be carried."""
    steps = frequency_hz / FREQUENCY_STEP_HZ
    # Compared before rounding, so NaN and infinities are refused too.
    if not 0 <= steps < MAX_FREQUENCY_RAW + 0.5:
        raise UsageError(f"{frequency_hz:g} Hz is outside 0-655.35 Hz")
    return round(steps)


def frequency_hz(raw: int) -> float:
    """The frequency in Hz of H6D/H6E/H6F data."""
    return round(raw * FREQUENCY_STEP_HZ, 2)


def decode_status(word: int, *, extended: bool = False) -> DriveStatus:
    """The vendor-neutral reading of H7A (or, with ``extended``, H79) data.

    Running and direction come from the fixed bits 1 and 2. At reference (SU), the overload
    warning (OL, stall prevention: the panel shows it as a warning) and, in H7A, the fault
    (ABC1) are the factory terminal assignments; H79 has a fixed fault bit (15).
    """
    bits = StatusBits(word & 0xFFFF)
    turning = bits & (StatusBits.FORWARD | StatusBits.REVERSE)
    running = bool(turning)
    return DriveStatus(
        word=word,
        running=running,
        fault=bool(bits & (StatusBits.FAULT if extended else StatusBits.ABC1)),
        warning=bool(bits & StatusBits.OL),
        at_reference=bool(bits & StatusBits.SU),
        reverse=turning == StatusBits.REVERSE if running else None,
    )


def flag_names(word: int, flags: type[StatusBits] | type[RunCommand]) -> dict[str, bool]:
    """Map each named bit of ``flags`` to whether it is set in ``word``."""
    return {str(flag.name).lower(): bool(word & flag) for flag in flags}
