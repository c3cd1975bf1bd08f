"""The FC control profile: control word, status word and reference scaling (§8).

Only valid with 8-10 Control Profile = [0] FC profile, the factory setting.
"""

from __future__ import annotations

import enum
from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.drive import ControlIntent, Motion


class ControlWord(enum.IntFlag):
    """CTW bits, named by what a 1 means (§8.1)."""

    PRESET_REFERENCE_LSB = 1 << 0
    PRESET_REFERENCE_MSB = 1 << 1
    NO_DC_BRAKE = 1 << 2  # 0 = DC brake
    NO_COAST = 1 << 3  # 0 = coast
    NO_QUICK_STOP = 1 << 4  # 0 = quick stop on the 3-81 ramp
    NO_FREEZE = 1 << 5  # 0 = hold the output frequency
    START = 1 << 6  # 0 = ramp stop
    RESET = 1 << 7  # acts on the 0 → 1 edge
    JOG = 1 << 8
    RAMP_2 = 1 << 9
    DATA_VALID = 1 << 10  # 0 = the drive ignores this control word
    RELAY_01 = 1 << 11
    RELAY_02 = 1 << 12
    SETUP_LSB = 1 << 13
    SETUP_MSB = 1 << 14
    REVERSE = 1 << 15


class StatusWord(enum.IntFlag):
    """STW bits, named by what a 1 means (§8.4)."""

    CONTROL_READY = 1 << 0
    DRIVE_READY = 1 << 1
    ENABLED = 1 << 2  # 0 = coasting
    TRIP = 1 << 3
    ERROR = 1 << 4  # a fault without a trip
    RESERVED_5 = 1 << 5
    TRIP_LOCK = 1 << 6  # needs a power cycle
    WARNING = 1 << 7
    AT_REFERENCE = 1 << 8  # ramp finished
    BUS_CONTROL = 1 << 9  # 0 = local operation
    FREQUENCY_OK = 1 << 10  # 0 = output at a speed limit
    RUNNING = 1 << 11  # in operation
    AUTO_RESTART_PENDING = 1 << 12  # stopped by over-temperature, resumes by itself
    VOLTAGE_EXCEEDED = 1 << 13
    TORQUE_EXCEEDED = 1 << 14
    TIMER_EXCEEDED = 1 << 15


# The bits every commanding word keeps at 1: no DC brake, no coast, no quick stop, use ramp.
_READY: Final = (
    ControlWord.NO_DC_BRAKE
    | ControlWord.NO_COAST
    | ControlWord.NO_QUICK_STOP
    | ControlWord.NO_FREEZE
    | ControlWord.DATA_VALID
)

IGNORED_CONTROL_WORD: Final = 0x0000  # bit 10 = 0: the drive ignores the word (§8.2)
REFERENCE_100_PCT: Final = 0x4000  # §8.5
REFERENCE_MIN_PCT: Final = -200.0
REFERENCE_MAX_PCT: Final = 0x7FFF / REFERENCE_100_PCT * 100.0


def control_word(intent: ControlIntent) -> int:
    """Return the CTW that commands ``intent`` (bit 10 always set)."""
    word = _READY
    motion = intent.motion
    if motion is Motion.RUN:
        word |= ControlWord.START
    elif motion is Motion.JOG:
        word |= ControlWord.START | ControlWord.JOG
    elif motion is Motion.COAST:  # §8.3: 0x0474, bit 6 stays 1
        word = (word | ControlWord.START) & ~ControlWord.NO_COAST
    elif motion is Motion.QUICK_STOP:  # §8.3: 0x046C, bit 6 stays 1
        word = (word | ControlWord.START) & ~ControlWord.NO_QUICK_STOP
    if intent.reverse:
        word |= ControlWord.REVERSE
    if intent.reset:
        word |= ControlWord.RESET
    return int(word)


def executed_motion(word: int) -> Motion | None:
    """The motion a drive executes by its last valid control word (16-00), if it is a stop.

    Read when a drive found running is not at its reference (status bit 8 = 0): it may be
    ramping down after a stop, with bit 11 still set while the output is above 0 Hz, and
    only the word it executes tells that from a change of speed. None: the word commands
    motion, or no valid word (bit 10 = 0) is there to say.
    """
    if not word & ControlWord.DATA_VALID:
        return None
    if not word & ControlWord.NO_COAST:
        return Motion.COAST
    if not word & ControlWord.NO_DC_BRAKE:  # DC braking, then stopped: a stop, not a coast
        return Motion.STOP
    if not word & ControlWord.NO_QUICK_STOP:
        return Motion.QUICK_STOP
    if not word & (ControlWord.START | ControlWord.JOG):
        return Motion.STOP
    return None


def encode_reference(percent: float) -> int:
    """Return the 16-bit MRV for ``percent`` (0x4000 = 100 %, two's complement)."""
    if not REFERENCE_MIN_PCT <= percent <= REFERENCE_MAX_PCT:
        raise UsageError(f"reference {percent} % is outside -200 … 199.99 %")
    return round(percent * REFERENCE_100_PCT / 100.0) & 0xFFFF


def decode_reference(raw: int) -> float:
    """Return the percentage of a 16-bit MRV or MAV."""
    signed = raw - 0x10000 if raw & 0x8000 else raw
    return signed * 100.0 / REFERENCE_100_PCT


def flag_names(word: int, flags: type[ControlWord] | type[StatusWord]) -> dict[str, bool]:
    """Map each named bit of ``flags`` to whether it is set in ``word``."""
    return {str(flag.name).lower(): bool(word & flag) for flag in flags}
