"""The read-only parameters of a simulated FC drive: measured values, words, logs, texts.

Each reading returns the value in the unit of the codec's table (Hz, A, kW, °C, …) and the
drive converts it with the same conversion index the master uses to read it back, so a
reading that leaves here as 50.0 Hz arrives at the master as 50.0 Hz. Counters (15-00 …
15-02) count whole units, as the drive's display does.

16-05 and 16-15 are N2 in some manuals and conversion index −2 in others (§10.1 [!]); like
the codec, the simulator uses the conversion index (raw 10000 = 100 %).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Final, Protocol

from fcmaster.protocol.danfoss_fc.profile import decode_reference
from fcmaster.sim.danfoss_fc.control import FcControl
from fcmaster.sim.danfoss_fc.parameters import ParameterStore
from fcmaster.sim.motor import Motor, MotorRating


class Source(Protocol):
    """What the readings read of a drive (an FcSimDrive), so they need not know the drive."""

    @property
    def control(self) -> FcControl:
        """The drive's control logic: words, reference, alarm log."""

    @property
    def motor(self) -> Motor:
        """The motor the drive turns."""

    @property
    def parameters(self) -> ParameterStore:
        """The drive's parameter values."""


_HP_PER_KW: Final = 1 / 0.7457
_RAMPING: Final = 1 << 0  # 16-94 bits (§9)
_OUT_OF_SPEED_RANGE: Final = 1 << 14


def _log_entry(drive: Source, index: int, field: int) -> float:
    log = drive.control.alarm_log
    return log[index][field] if index < len(log) else 0.0


def _ext_status(drive: Source) -> int:
    word = _RAMPING if drive.motor.is_ramping else 0
    return word | (_OUT_OF_SPEED_RANGE if drive.control.at_speed_limit else 0)


Reading = Callable[[Source, int], float]

# PNU → value in the table's unit; ``index`` is the array index (0 for plain parameters).
READINGS: Final[dict[int, Reading]] = {
    1500: lambda d, i: math.floor(d.motor.operating_s / 3600.0),
    1501: lambda d, i: math.floor(d.motor.running_s / 3600.0),
    1502: lambda d, i: math.floor(d.motor.energy_kwh),
    1530: lambda d, i: _log_entry(d, i, 0),
    1531: lambda d, i: 0.0,  # alarm-specific value: none simulated
    1532: lambda d, i: math.floor(_log_entry(d, i, 1)),
    1600: lambda d, i: d.control.control_word,
    1601: lambda d, i: d.control.reference_hz,
    1602: lambda d, i: d.control.reference_pct,
    1603: lambda d, i: d.control.status_word,
    1605: lambda d, i: decode_reference(d.control.main_actual_value),
    1610: lambda d, i: d.motor.power_kw,
    1611: lambda d, i: d.motor.power_kw * _HP_PER_KW,
    1612: lambda d, i: d.motor.voltage_v,
    1613: lambda d, i: abs(d.motor.frequency_hz),
    1614: lambda d, i: d.motor.current_a,
    1615: lambda d, i: abs(d.motor.frequency_hz) / d.parameters.value(414) * 100.0,
    1616: lambda d, i: d.motor.torque_fraction * d.motor.rating.torque_nm,
    1617: lambda d, i: d.motor.speed_rpm,
    1618: lambda d, i: d.motor.motor_thermal_pct,
    1622: lambda d, i: d.motor.torque_fraction * 100.0,
    1630: lambda d, i: d.motor.dc_link_v if d.motor.rating.mains_v else 0.0,
    1634: lambda d, i: d.motor.heatsink_c,
    1635: lambda d, i: d.motor.motor_thermal_pct * 0.8,  # the inverter is sized with margin
    1690: lambda d, i: d.control.alarm_word,
    1691: lambda d, i: 0,  # product-specific words: nothing simulated
    1692: lambda d, i: d.control.warning_word,
    1693: lambda d, i: 0,
    1694: lambda d, i: _ext_status(d),
}


def identification_texts(address: int, rating: MotorRating) -> dict[int, str]:
    """15-40 … 15-53 for a drive at ``address`` sized for ``rating``."""
    power = f"P{rating.power_kw:.1f}".replace(".", "K")  # 5.5 kW → P5K5
    typecode = f"FC-302{power}T5E20H1XGXXXXSXXXXAXBXCXXXXDX"
    return {
        1540: "FC-302",
        1541: power,
        1542: "T5",
        1543: "48.20",
        1544: typecode,
        1545: typecode,
        1546: "131B0078",
        1548: "130B1107",
        1549: "SW48.20",
        1550: "SW48.01",
        1551: f"{address:03d}123G456",  # distinct per drive, like real serial numbers
        1553: f"{address:03d}456X789",
    }
