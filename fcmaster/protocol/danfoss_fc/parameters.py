"""FC parameters: numbering, data types, conversion and the table a gateway uses (§6-§7, §10).

A parameter is written the manual's way, ``"16-13"`` (group 16, number 13), and travels as
PNU = 100 × group + number in the low twelve bits of PKE. Values are integers on the wire;
the conversion index turns them into engineering units (16-13 with index −1: raw 503 is
50.3 Hz). Indices 67, 70, 74, 75, 77 and 100 name a unit and do not scale (§7.2).
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass
from typing import Final

from fcmaster.errors import MalformedReply, UsageError
from fcmaster.protocol.danfoss_fc.telegram import RequestAk

MAX_PNU: Final = 0xFFF
_N2_100_PCT: Final = 0x4000  # N2 standardised value (§7.1, data type 33)
_NOTATION = re.compile(r"^\s*(\d{1,2})-(\d{2})\s*$")


class DataType(enum.IntEnum):
    """Data types as the manuals number them (§7.1)."""

    INT16 = 3
    INT32 = 4
    UINT8 = 5
    UINT16 = 6
    UINT32 = 7
    TEXT = 9
    N2 = 33  # 0x4000 = 100 %
    V2 = 35  # 16 flags


# conversion index → unit it stands for instead of a power of ten
UNIT_INDICES: Final[dict[int, str]] = {67: "rpm", 70: "min", 74: "h", 75: "kWh", 77: "d", 100: "°C"}

# Base-unit exponent of a display unit: a "[kW]" parameter with index 1 counts 10 W steps.
_UNIT_EXPONENT: Final[dict[str, int]] = {"kW": 3, "ms": -3}

_WIDTH: Final[dict[DataType, tuple[int, bool]]] = {  # bits on the wire, signed
    DataType.INT16: (16, True),
    DataType.INT32: (32, True),
    DataType.UINT8: (8, False),
    DataType.UINT16: (16, False),
    DataType.UINT32: (32, False),
    DataType.N2: (16, True),
    DataType.V2: (16, False),
}


def parse_parameter(text: str) -> int:
    """Return the PNU of a parameter written ``"16-13"`` (or a plain legacy number)."""
    match = _NOTATION.match(text)
    if match:
        group, number = int(match[1]), int(match[2])
        pnu = 100 * group + number
    elif text.strip().isdigit():
        try:
            pnu = int(text)
        except ValueError:  # isdigit() passes "²"; int() refuses more than 4300 digits
            raise UsageError(f"parameter {text[:12]!r} is not a PNU (0-4095)") from None
    else:
        raise UsageError(f"parameter {text!r} is not written like 16-13")
    if pnu > MAX_PNU:
        raise UsageError(f"parameter {text} (PNU {pnu}) does not fit in 12 bits (up to 40-95)")
    return pnu


def format_parameter(pnu: int) -> str:
    """Return the manual's notation of a PNU: 1613 → ``"16-13"``."""
    return f"{pnu // 100}-{pnu % 100:02d}"


@dataclass(slots=True, frozen=True, kw_only=True)
class ParameterSpec:
    """What the master needs to know to read and write one parameter."""

    pnu: int
    name: str
    data_type: DataType | None  # None: not in the table; the reply's AK gives the width
    conversion: int = 0
    unit: str = ""
    writable: bool = False
    array_length: int = 0  # 0 = not an array

    @property
    def number(self) -> str:
        """The manual's notation, e.g. ``"16-13"``."""
        return format_parameter(self.pnu)

    @property
    def is_text(self) -> bool:
        """Whether the value travels in a text block (AK F)."""
        return self.data_type is DataType.TEXT

    @property
    def is_double_word(self) -> bool:
        """Whether the value is 32 bits wide."""
        return self.data_type in (DataType.INT32, DataType.UINT32)

    @property
    def exponent(self) -> int:
        """Power of ten from the raw integer to the value in ``unit``."""
        if self.conversion in UNIT_INDICES:
            return 0
        return self.conversion - _UNIT_EXPONENT.get(self.unit, 0)

    def write_ak(self, raw: int, *, eeprom: bool = False) -> RequestAk:
        """AK that writes ``raw`` to this parameter: word or double word, RAM or + EEPROM."""
        if self.is_double_word or (self.data_type is None and not 0 <= raw <= 0xFFFF):
            return RequestAk.WRITE_DWORD_EEPROM if eeprom else RequestAk.WRITE_DWORD
        return RequestAk.WRITE_WORD_EEPROM if eeprom else RequestAk.WRITE_WORD

    def raw_from_pwe(self, pwe: int, *, double_word: bool) -> int:
        """The raw integer in a PWE, by data type (8/16-bit types from PWElow).

        ``double_word`` is what the AK says (reply AK 2, request AK 3/D). Only a parameter
        not in the table goes by it: drives answer 32-bit reads with AK 1 or 2 (§6.3).
        """
        if self.data_type is None:
            bits, signed = (32 if double_word else 16), False
        elif self.data_type is DataType.TEXT:
            raise MalformedReply(f"{self.number} is a text parameter, not a value")
        else:
            bits, signed = _WIDTH[self.data_type]
        raw = pwe & ((1 << bits) - 1)
        if bits == 8 and pwe & 0xFF00:
            # An 8-bit value with bits set above it is not one: refuse rather than mask.
            raise MalformedReply(f"{self.number}: 0x{pwe & 0xFFFF:04X} does not fit in 8 bits")
        if signed and raw >> (bits - 1):
            raw -= 1 << bits
        return raw

    def pwe_from_raw(self, raw: int) -> int:
        """The PWE that carries ``raw``; raise UsageError if the type cannot hold it."""
        if self.data_type is None:
            bits, signed = (16, False) if 0 <= raw <= 0xFFFF else (32, raw < 0)
        elif self.data_type is DataType.TEXT:
            raise UsageError(f"{self.number} is a text parameter, not a value")
        else:
            bits, signed = _WIDTH[self.data_type]
        low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
        if not low <= raw <= high:
            raise UsageError(f"{self.number}: raw value {raw} is outside {low}…{high}")
        return raw & ((1 << bits) - 1) if bits == 32 else raw & 0xFFFF

    def to_value(self, raw: int) -> float:
        """Raw integer → engineering value in ``unit``."""
        if self.data_type is DataType.N2:  # 0x4000 = 100 %, whatever the conversion index
            return raw * 100.0 / _N2_100_PCT
        exponent = self.exponent
        return raw * 10.0**exponent if exponent >= 0 else raw / 10.0**-exponent

    def to_raw(self, value: float) -> int:
        """Engineering value in ``unit`` → raw integer, rounded to the parameter's resolution."""
        if self.data_type is DataType.N2:
            return round(value * _N2_100_PCT / 100.0)
        exponent = self.exponent
        return round(value / 10.0**exponent if exponent >= 0 else value * 10.0**-exponent)


def _p(
    number: str,
    name: str,
    data_type: DataType,
    conversion: int = 0,
    unit: str = "",
    *,
    writable: bool = False,
    array_length: int = 0,
) -> ParameterSpec:
    return ParameterSpec(
        pnu=parse_parameter(number),
        name=name,
        data_type=data_type,
        conversion=conversion,
        unit=unit,
        writable=writable,
        array_length=array_length,
    )


_T = DataType
# FC 301/302 numbering (§10). Writable entries are the ones a gateway commonly sets.
PARAMETERS: Final[dict[int, ParameterSpec]] = {
    spec.pnu: spec
    for spec in (
        _p("3-02", "Minimum Reference", _T.INT32, -3, writable=True),
        _p("3-03", "Maximum Reference", _T.INT32, -3, writable=True),
        _p("3-19", "Jog Speed [Hz]", _T.UINT16, -1, "Hz", writable=True),
        _p("3-41", "Ramp 1 Ramp Up Time", _T.UINT32, -2, "s", writable=True),
        _p("3-42", "Ramp 1 Ramp Down Time", _T.UINT32, -2, "s", writable=True),
        _p("3-51", "Ramp 2 Ramp Up Time", _T.UINT32, -2, "s", writable=True),
        _p("3-52", "Ramp 2 Ramp Down Time", _T.UINT32, -2, "s", writable=True),
        _p("3-81", "Quick Stop Ramp Time", _T.UINT32, -2, "s", writable=True),
        _p("4-12", "Motor Speed Low Limit [Hz]", _T.UINT16, -1, "Hz", writable=True),
        _p("4-14", "Motor Speed High Limit [Hz]", _T.UINT16, -1, "Hz", writable=True),
        _p("8-03", "Control Word Timeout Time", _T.UINT32, -1, "s", writable=True),
        _p("8-04", "Control Word Timeout Function", _T.UINT8, writable=True),
        _p("8-30", "Protocol", _T.UINT8, writable=True),
        _p("8-31", "Address", _T.UINT8, writable=True),
        _p("8-32", "FC Port Baud Rate", _T.UINT8, writable=True),
        _p("8-33", "Parity / Stop Bits", _T.UINT8, writable=True),
        _p("8-35", "Minimum Response Delay", _T.UINT16, -3, "ms", writable=True),
        _p("8-36", "Maximum Response Delay", _T.UINT16, -3, "ms", writable=True),
        _p("8-37", "Maximum Inter-Char Delay", _T.UINT16, -5, "ms", writable=True),
        _p("15-00", "Operating Hours", _T.UINT32, 74, "h"),
        _p("15-01", "Running Hours", _T.UINT32, 74, "h"),
        _p("15-02", "kWh Counter", _T.UINT32, 75, "kWh"),
        _p("15-30", "Alarm Log: Error Code", _T.UINT8, array_length=10),
        _p("15-31", "Alarm Log: Value", _T.INT16, array_length=10),
        _p("15-32", "Alarm Log: Time", _T.UINT32, 0, "s", array_length=10),
        _p("15-40", "FC Type", _T.TEXT),
        _p("15-41", "Power Section", _T.TEXT),
        _p("15-42", "Voltage", _T.TEXT),
        _p("15-43", "Software Version", _T.TEXT),
        _p("15-44", "Ordered Typecode String", _T.TEXT),
        _p("15-45", "Actual Typecode String", _T.TEXT),
        _p("15-46", "Frequency Converter Ordering No", _T.TEXT),
        _p("15-48", "LCP Id No", _T.TEXT),
        _p("15-49", "SW ID Control Card", _T.TEXT),
        _p("15-50", "SW ID Power Card", _T.TEXT),
        _p("15-51", "Frequency Converter Serial Number", _T.TEXT),
        _p("15-53", "Power Card Serial Number", _T.TEXT),
        _p("16-00", "Control Word", _T.V2),
        _p("16-01", "Reference [Unit]", _T.INT32, -3),
        _p("16-02", "Reference [%]", _T.INT16, -1, "%"),
        _p("16-03", "Status Word", _T.V2),
        _p("16-05", "Main Actual Value [%]", _T.N2, -2, "%"),
        _p("16-10", "Power [kW]", _T.INT32, 1, "kW"),
        _p("16-11", "Power [hp]", _T.INT32, -2, "hp"),
        _p("16-12", "Motor Voltage", _T.UINT16, -1, "V"),
        _p("16-13", "Frequency", _T.UINT16, -1, "Hz"),
        _p("16-14", "Motor Current", _T.INT32, -2, "A"),
        _p("16-15", "Frequency [%]", _T.N2, -2, "%"),
        _p("16-16", "Torque [Nm]", _T.INT32, -1, "Nm"),
        _p("16-17", "Speed [RPM]", _T.INT32, 67, "rpm"),
        _p("16-18", "Motor Thermal", _T.UINT8, 0, "%"),
        _p("16-22", "Torque [%]", _T.INT16, 0, "%"),
        _p("16-30", "DC Link Voltage", _T.UINT16, 0, "V"),
        _p("16-34", "Heatsink Temp.", _T.UINT8, 100, "°C"),
        _p("16-35", "Inverter Thermal", _T.UINT8, 0, "%"),
        _p("16-90", "Alarm Word", _T.UINT32),
        _p("16-91", "Alarm Word 2", _T.UINT32),
        _p("16-92", "Warning Word", _T.UINT32),
        _p("16-93", "Warning Word 2", _T.UINT32),
        _p("16-94", "Ext. Status Word", _T.UINT32),
    )
}


def lookup(pnu: int) -> ParameterSpec:
    """The table entry for ``pnu``, or a nameless one that decodes by the reply's AK."""
    spec = PARAMETERS.get(pnu)
    if spec is None:
        return ParameterSpec(pnu=pnu, name="", data_type=None)
    return spec


# -- parameter sets (fcmaster.protocol.parameter_set) ------------------------------------

# A set is every writable parameter of the table, in table order.
SET_MEMBERS: Final = tuple((s.number, s.name) for s in PARAMETERS.values() if s.writable)
IDENTITY: Final = tuple(
    (number, PARAMETERS[parse_parameter(number)].name)
    for number in ("15-40", "15-41", "15-42", "15-43", "15-51")
)
IDENTITY_MATCH: Final = frozenset({"15-40"})  # FC type: a set fits drives of its own type
# The programming guides mark each parameter "change during operation" TRUE or FALSE, and a
# drive reports it as bit 13 of description element 21 (FC 300 Design Guide, "additional
# characteristics"); a FALSE one written while running is refused with error 17. Those
# marks for this table's members were not at hand, so none is taken as changeable while the
# motor turns: a restore writes them only while stopped. Fill in from the guide's lists.
CHANGEABLE_WHILE_RUNNING: Final[frozenset[str]] = frozenset()
# Protocol, address, baud rate, parity: a restore that changed them would lose the drive.
LINK_SETTINGS: Final = frozenset({"8-30", "8-31", "8-32", "8-33"})
# The set holds no factory reset or operation mode (14-22 "initialise" resets the drive at
# its next power-up): a restore writes nothing outside the set.
FREQUENCY_CEILINGS: Final = frozenset({"4-14"})  # Motor Speed High Limit [Hz]
# Ranges of the programming guide (FC 301/302) that hold whatever the other settings are:
# ramp times 0.01-3600 s, the control-word timeout 0.1-18000 s.
SET_RANGES: Final = (
    *((number, 0.01, 3600.0) for number in ("3-41", "3-42", "3-51", "3-52", "3-81")),
    ("8-03", 0.1, 18000.0),
)
