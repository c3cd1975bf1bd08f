"""The Modbus register map: which register of which unit shows what of which drive.

Each drive is one unit id (``modbus_unit``, else its bus address). Every unit has the same
layout, so a PLC program written for one drive serves them all:

- **input registers** 0-13 hold the drive state (``online``, ``age_s``, ``status_word``, …;
  :data:`STATE_REGISTERS`), 14-15 are reserved (they read 0), and from 16 on every monitored
  value takes four registers: the value in its unit as ``f32`` and the drive's raw integer
  as ``i32``;
- **holding registers** 0 ``command`` (write an action code; reads 0) and 1
  ``reference_hz``.

Registers are served from the fleet state in memory; a read never causes a bus request.
32-bit values put their high word first. A value the gateway does not know right now —
the drive is offline or has never answered, the value was not read yet, or it does not fit
its register — reads as its type's *unknown* mark: ``0xFFFF`` (u16), ``0x8000`` (i16),
``0xFFFFFFFF`` (u32), ``0x80000000`` (i32), NaN (f32). Only ``online`` and ``age_s`` keep
telling the truth about an offline drive: ``online`` is 0, ``age_s`` the seconds since its
last good reply. So an offline drive's last values are never shown as if they were current.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

from fcmaster.bus.codecs import codec_for, monitor_keys
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.protocol.drive import pct_to_hz
from fcmaster.protocol.registry import spec_for
from fcmaster.state import DriveState

ACTIONS: Final = {  # the `command` register's action codes (DESIGN.md "Modbus TCP")
    1: "start",
    2: "stop",
    3: "coast",
    4: "quick_stop",
    5: "reset",
    6: "forward",
    7: "reverse",
    8: "jog",
}
COMMAND_ADDRESS: Final = 0
REFERENCE_ADDRESS: Final = 1
REFERENCE_DECIMALS: Final = 2  # reference_hz counts 0.01 Hz
VALUES_START: Final = 16  # monitored values begin here; 14-15 are kept for later state
AGE_UNKNOWN_S: Final = 6553.5  # age_s saturates at its unknown mark: never, or older

_WIDTH: Final = {"u16": 1, "i16": 1, "u32": 2, "i32": 2, "f32": 2}
_RANGE: Final = {
    "u16": (0, 0xFFFE),  # the top value is the unknown mark
    "i16": (-0x7FFF, 0x7FFF),
    "u32": (0, 0xFFFFFFFE),
    "i32": (-0x7FFFFFFF, 0x7FFFFFFF),
}
_UNKNOWN: Final = {"u16": [0xFFFF], "i16": [0x8000], "u32": [0xFFFF, 0xFFFF], "i32": [0x8000, 0]}
_NAN: Final = list(struct.unpack(">HH", struct.pack(">f", math.nan)))

Reader = Callable[[DriveState, float], float | None]  # (state, wall-clock now) → value


@dataclass(slots=True, frozen=True, kw_only=True)
class Register:
    """One value in the map: one register, or two for 32-bit types."""

    table: str  # "input" | "holding"
    address: int
    name: str
    type: str  # u16 | i16 | u32 | i32 | f32
    decimals: int = 0  # the value is the register's integer / 10**decimals
    unit: str = ""
    read: Reader

    @property
    def width(self) -> int:
        """Registers taken."""
        return _WIDTH[self.type]

    @property
    def scale(self) -> float:
        """What one count of the register is worth in ``unit``."""
        return 10.0**-self.decimals

    def encode(self, value: float | None) -> list[int]:
        """The register words for ``value`` (None, NaN or out of range: the unknown mark)."""
        if self.type == "f32":
            try:
                return list(struct.unpack(">HH", struct.pack(">f", value)))
            except (OverflowError, struct.error):  # None, or beyond what a float32 holds
                return list(_NAN)
        if value is None or not math.isfinite(value):
            return list(_UNKNOWN[self.type])
        raw = round(value * 10**self.decimals)
        low, high = _RANGE[self.type]
        if not low <= raw <= high:
            return list(_UNKNOWN[self.type])
        if self.width == 1:
            return [raw & 0xFFFF]
        raw &= 0xFFFFFFFF
        return [raw >> 16, raw & 0xFFFF]


@dataclass(slots=True, frozen=True, kw_only=True)
class UnitMap:
    """The registers of one unit id, which is one drive."""

    unit_id: int
    bus: str
    drive: DrivePlan
    inputs: tuple[Register, ...]
    holdings: tuple[Register, ...]

    def table(self, name: str) -> tuple[Register, ...]:
        """The input or holding registers."""
        return self.inputs if name == "input" else self.holdings

    def size(self, table: str) -> int:
        """Registers in ``table``, from 0 to the end of the last value."""
        last = self.table(table)[-1]
        return last.address + last.width

    def words(self, table: str, state: DriveState, now: float) -> list[int]:
        """Every register of ``table`` for ``state`` at wall-clock time ``now``."""
        words = [0] * self.size(table)
        for register in self.table(table):
            words[register.address : register.address + register.width] = register.encode(
                register.read(state, now)
            )
        return words


@dataclass(slots=True, frozen=True)
class RegisterMap:
    """Every unit of a configuration."""

    units: dict[int, UnitMap]

    def entries(self) -> list[dict[str, Any]]:
        """The map as DESIGN.md's entries, for ``fcmaster modbus-map --json``."""
        return [
            {
                "unit_id": unit.unit_id,
                "bus": unit.bus,
                "drive": unit.drive.name,
                "table": register.table,
                "address": register.address,
                "name": register.name,
                "type": register.type,
                "scale": register.scale,
                "unit": register.unit,
            }
            for unit in self.units.values()
            for register in (*unit.inputs, *unit.holdings)
        ]


def register_map(lines: Sequence[LinePlan], unit_ids: Mapping[str, int]) -> RegisterMap:
    """The map of the drives of ``lines``, each at its unit id in ``unit_ids`` (by name)."""
    units = {}
    for line in lines:
        for drive in line.drives:
            unit_id = unit_ids[drive.name]
            units[unit_id] = UnitMap(
                unit_id=unit_id,
                bus=line.name,
                drive=drive,
                inputs=(*STATE_REGISTERS, *_value_registers(line, drive)),
                holdings=_holdings(drive),
            )
    return RegisterMap(dict(sorted(units.items())))


# -- what each register reads ---------------------------------------------------------------


def _fresh(read: Callable[[DriveState], float | None]) -> Reader:
    """A reader that knows nothing while the drive is offline."""
    return lambda state, _now: read(state) if state.online else None


def _age(state: DriveState, now: float) -> float | None:
    if state.updated_at is None:
        return None
    return min(max(0.0, now - state.updated_at), AGE_UNKNOWN_S)


def _first(conditions: tuple[Any, ...]) -> float:
    return conditions[0].code if conditions else 0


def _u16(
    table: str, address: int, name: str, read: Reader, decimals: int = 0, unit: str = ""
) -> Register:
    return Register(
        table=table, address=address, name=name, type="u16", decimals=decimals, unit=unit, read=read
    )


STATE_REGISTERS: Final = (
    _u16("input", 0, "online", lambda state, _now: float(state.online)),
    _u16("input", 1, "age_s", _age, 1, "s"),
    _u16("input", 2, "status_word", _fresh(lambda s: s.status_word)),
    _u16("input", 3, "running", _fresh(lambda s: s.running)),
    _u16("input", 4, "fault", _fresh(lambda s: s.fault)),
    _u16("input", 5, "warning", _fresh(lambda s: s.warning)),
    _u16("input", 6, "direction", _fresh(lambda s: s.direction == "reverse")),  # 1 reverse
    _u16("input", 7, "at_reference", _fresh(lambda s: s.at_reference)),
    _u16("input", 8, "output_frequency_hz", _fresh(lambda s: s.output_frequency_hz), 2, "Hz"),
    _u16("input", 9, "reference_pct", _fresh(lambda s: s.reference_pct), 2, "%"),
    _u16("input", 10, "alarm_code", _fresh(lambda s: _first(s.alarms))),
    _u16("input", 11, "warning_code", _fresh(lambda s: _first(s.warnings))),
    _u16("input", 12, "alarm_count", _fresh(lambda s: len(s.alarms))),
    _u16("input", 13, "warning_count", _fresh(lambda s: len(s.warnings))),
)


def _holdings(drive: DrivePlan) -> tuple[Register, ...]:
    nominal = drive.nominal_frequency_hz

    def reference_hz(state: DriveState) -> float | None:
        return None if state.reference_pct is None else pct_to_hz(state.reference_pct, nominal)

    return (
        _u16("holding", COMMAND_ADDRESS, "command", lambda _state, _now: 0.0),
        _u16("holding", REFERENCE_ADDRESS, "reference_hz", _fresh(reference_hz), 2, "Hz"),
    )


def _value_registers(line: LinePlan, drive: DrivePlan) -> list[Register]:
    keys = monitor_keys(codec_for(line), drive)
    # a Modbus RTU drive's units are its profile's
    unit_of = spec_for(line.protocol).parameters_of(line, drive.profile).unit_of
    registers = []
    for n, key in enumerate(dict.fromkeys(keys)):
        address = VALUES_START + 4 * n

        def value(state: DriveState, name: str = key.name) -> float | None:
            measured = state.values.get(name)
            return measured.value if measured and isinstance(measured.value, float | int) else None

        def raw(state: DriveState, name: str = key.name) -> float | None:
            measured = state.values.get(name)
            if measured is None or measured.raw is None:
                return None
            # The bits as the drive sent them: an unsigned 32-bit word (an alarm word with
            # bit 31 set) shows as its two's complement, so DWORD access sees every bit.
            return measured.raw - (1 << 32) if measured.raw >= 1 << 31 else measured.raw

        registers.append(
            Register(table="input", address=address, name=key.name, type="f32", unit=unit_of(key),
                     read=_fresh(value))
        )  # fmt: skip
        registers.append(
            Register(table="input", address=address + 2, name=f"{key.name}.raw", type="i32",
                     read=_fresh(raw))
        )  # fmt: skip
    return registers
