"""The running values a simulated ENC drive reports to command 11 (§4.1) and its state word (§6).

Each reading returns the raw 16-bit value in the unit of the codec's table
(:data:`fcmaster.protocol.enc.RUNNING_VALUES`), so a value that leaves here as 4000 in
0.01 Hz reads 40.00 Hz at the master. Values are unsigned on the wire: magnitudes are sent,
and a reading beyond 0xFFFF is held at 0xFFFF.

Terminals and analog inputs are not simulated and read 0. Running time (0007) counts this
power-up's running hours, accumulated running time (0008) the motor's running hours plus
what the drive brought from earlier service (:data:`EARLIER_RUNNING_H`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Final, Protocol

from fcmaster.protocol.enc.parameters import RUNNING_VALUES, StateWord
from fcmaster.sim.enc.control import EncControl
from fcmaster.sim.motor import Motor


class Source(Protocol):
    """What the readings read of a drive (an EncSimDrive), so they need not know the drive."""

    @property
    def control(self) -> EncControl:
        """The drive's control logic: set frequency, direction, jogging, undervoltage."""

    @property
    def motor(self) -> Motor:
        """The motor the drive turns."""


EARLIER_RUNNING_H: Final = 1200.0


def state_word(drive: Source) -> int:
    """The running state word (§6) for the drive's present state."""
    control, motor = drive.control, drive.motor
    word = StateWord(0)
    if motor.output_on:
        word |= StateWord.RUNNING
        word |= StateWord.JOGGING if control.jogging else StateWord.NORMAL_RUN
    if control.undervoltage:
        word |= StateWord.UNDERVOLTAGE
    # The direction of the output while it turns, else the one the next run will take.
    if motor.frequency_hz < 0 or (not motor.frequency_hz and control.reverse):
        word |= StateWord.REVERSE
    return int(word)


Reading = Callable[[Source], float]

# command-11 index → value in the table's unit
READINGS: Final[dict[int, Reading]] = {
    0x00: lambda d: d.control.set_hz,
    0x01: lambda d: abs(d.motor.frequency_hz),
    0x02: lambda d: d.motor.voltage_v,
    0x03: lambda d: d.motor.current_a,
    0x04: lambda d: d.motor.dc_link_v if d.motor.rating.mains_v else 0.0,
    0x05: lambda d: abs(d.motor.speed_rpm),
    0x06: lambda d: d.motor.heatsink_c,
    0x07: lambda d: math.floor(d.motor.running_s / 3600.0),
    0x08: lambda d: math.floor(EARLIER_RUNNING_H + d.motor.running_s / 3600.0),
    0x09: lambda d: 0.0,
    0x0A: lambda d: 0.0,
    0x0B: lambda d: 0.0,
    0x0C: lambda d: 0.0,
    0x0D: lambda d: 0.0,
    0x0E: lambda d: 0.0,
    0x0F: lambda d: state_word(d),
}


def raw_reading(drive: Source, index: int) -> int:
    """The raw data of running value ``index`` (KeyError if there is none)."""
    value = READINGS[index](drive)
    raw = RUNNING_VALUES[index][1].to_raw(max(value, 0.0))
    return min(raw, 0xFFFF)
