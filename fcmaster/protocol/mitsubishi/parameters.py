"""What ``parameter()`` accepts, and parameters reached through the link-parameter page.

Names accepted (case and spaces do not matter):

* a parameter number the way the manuals and the panel write it: ``Pr.7``, ``Pr 7``,
  ``pr7``, ``P7`` or ``7`` (decimal, Pr.0-Pr.899). Normalised to ``Pr.7``. A parameter is
  read with code ``number mod 100`` and written with 0x80 + that, after HFF has set the page
  ``number div 100`` (§9). Pr.900 and up are refused: the calibration parameters need HEC
  as well, and their codes and page differ by family (the FR-F500 manual puts Pr.900-905
  on page H01).
* an instruction code of a page-independent item (``instructions``): ``H7A``, ``h7a``,
  ``0x7A``, or ``7A`` when it holds a letter (``70`` is Pr.70; output current is ``H70``).
  A write code names the same item as its read code (``HED`` is ``H6D``). Normalised to
  ``H`` + the item's code. Codes 00-63 and 80-E3 are parameter codes whose meaning depends
  on the page, so they are refused with a hint to name the parameter instead.

Values are in the parameter's setting unit (Pr.7 = 5.0 s is sent as 50). The table below
knows the increment of the parameters a gateway touches; any other parameter is read and
written in raw setting increments (unit ""). The settings 9999 and 8888 travel as HFFFF and
HFFFE (§9, [M?]), so 9999 and 8888 read back as themselves, and writing either value sends
the special code; a raw 9999 (e.g. 99.99 Hz of a parameter not in the table) cannot be
written that way.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.codec import ParameterKey, ParameterValue
from fcmaster.protocol.mitsubishi.instructions import BY_CODE, Instruction, is_paged, item_value

MAX_PARAMETER: Final = 899
INSTRUCTION_KEY_BASE: Final = 0x10000  # ParameterKey.code of an instruction item
PARAMETER_DIGITS: Final = (4, 6)  # A/E or A2/E2 (§6, §9)
SETTING_9999: Final = 0xFFFF
SETTING_8888: Final = 0xFFFE
MAX_RAW: Final = 0xFFFFFF  # six digits

_PARAMETER = re.compile(r"(?:pr?\.?)?(\d{1,4})", re.IGNORECASE | re.ASCII)
_CODE = re.compile(r"(?:h|0x)?([0-9a-f]{1,2})", re.IGNORECASE | re.ASCII)


@dataclass(slots=True, frozen=True, kw_only=True)
class ParameterSpec:
    """A parameter reached through the page: its number, increment and unit."""

    number: int
    name: str = ""
    step: float = 1.0
    unit: str = ""

    @property
    def page(self) -> int:
        """The HFF data that selects this parameter's hundred."""
        return self.number // 100

    @property
    def read_code(self) -> int:
        """The instruction code that reads it (on its page)."""
        return self.number % 100

    @property
    def write_code(self) -> int:
        """The instruction code that writes it (on its page)."""
        return 0x80 + self.read_code

    def to_raw(self, value: float) -> int:
        """The data for ``value`` in the parameter's unit; UsageError if it cannot travel."""
        if value == 9999:
            return SETTING_9999
        if value == 8888:
            return SETTING_8888
        steps = value / self.step
        # Compared before rounding, so NaN and infinities are refused too.
        raw = round(steps) if 0 <= steps < MAX_RAW + 0.5 else -1
        if raw < 0 or raw in (SETTING_8888, SETTING_9999):
            raise UsageError(f"Pr.{self.number}: {value:g} {self.unit} cannot be sent".rstrip())
        return raw

    def to_value(self, raw: int) -> float:
        """The value of ``raw`` data in the parameter's unit (9999/8888 as themselves)."""
        if raw == SETTING_9999:
            return 9999.0
        if raw == SETTING_8888:
            return 8888.0
        return round(raw * self.step, 6)


def _p(number: int, name: str, step: float = 1.0, unit: str = "") -> ParameterSpec:
    return ParameterSpec(number=number, name=name, step=step, unit=unit)


# 700-series increments [M?]. Pr.7/8 are 0.01 s when Pr.21 = 1 (A700/F700).
PARAMETERS: Final[dict[int, ParameterSpec]] = {
    spec.number: spec
    for spec in (
        _p(0, "torque boost", 0.1, "%"),
        _p(1, "maximum frequency", 0.01, "Hz"),
        _p(2, "minimum frequency", 0.01, "Hz"),
        _p(3, "base frequency", 0.01, "Hz"),
        _p(4, "multi-speed setting (high speed)", 0.01, "Hz"),
        _p(5, "multi-speed setting (middle speed)", 0.01, "Hz"),
        _p(6, "multi-speed setting (low speed)", 0.01, "Hz"),
        _p(7, "acceleration time", 0.1, "s"),
        _p(8, "deceleration time", 0.1, "s"),
        _p(9, "electronic thermal O/L relay", 0.01, "A"),
        _p(13, "starting frequency", 0.01, "Hz"),
        _p(15, "jog frequency", 0.01, "Hz"),
        _p(16, "jog acceleration/deceleration time", 0.1, "s"),
        _p(18, "high speed maximum frequency", 0.01, "Hz"),
        _p(20, "acceleration/deceleration reference frequency", 0.01, "Hz"),
        _p(77, "parameter write selection"),
        _p(78, "reverse rotation prevention selection"),
        _p(79, "operation mode selection"),
        _p(117, "PU communication station number"),
        _p(118, "PU communication speed (× 100 bps)"),
        _p(119, "PU communication stop bit length / data length"),
        _p(120, "PU communication parity check"),
        _p(121, "PU communication retry count"),
        _p(122, "PU communication check time interval", 0.1, "s"),
        _p(123, "PU communication waiting time setting", 1.0, "ms"),
        _p(124, "PU communication CR/LF selection"),
        _p(331, "RS-485 communication station number"),
        _p(332, "RS-485 communication speed (× 100 bps)"),
        _p(333, "RS-485 communication stop bit length / data length"),
        _p(334, "RS-485 communication parity check"),
        _p(335, "RS-485 communication retry count"),
        _p(336, "RS-485 communication check time interval", 0.1, "s"),
        _p(337, "RS-485 communication waiting time setting", 1.0, "ms"),
        _p(338, "communication operation command source"),
        _p(339, "communication speed command source"),
        _p(340, "communication startup mode selection"),
        _p(341, "RS-485 communication CR/LF selection"),
        _p(342, "communication EEPROM write selection"),
        _p(549, "protocol selection"),
        _p(551, "PU mode operation command source selection"),
    )
}


def lookup(number: int) -> ParameterSpec:
    """The spec of Pr.``number``; a raw one (step 1, no unit) if the table lacks it."""
    return PARAMETERS.get(number) or ParameterSpec(number=number)


def parameter_key(number: int) -> ParameterKey:
    """The key of Pr.``number``; UsageError outside Pr.0-Pr.899."""
    if not 0 <= number <= MAX_PARAMETER:
        raise UsageError(
            f"Pr.{number} is outside Pr.0-Pr.899: Pr.900 and up (calibration) are reached "
            "through family-specific codes and HEC, which this codec does not send"
        )
    return ParameterKey(f"Pr.{number}", number)


def instruction_key(item: Instruction) -> ParameterKey:
    """The key of a page-independent item."""
    return ParameterKey(item.key_name, INSTRUCTION_KEY_BASE + item.code)


def parse_parameter(text: str) -> ParameterKey:
    """The key of a parameter or item written as the module docstring says."""
    compact = re.sub(r"\s+", "", text)
    match = _PARAMETER.fullmatch(compact)
    if match:
        return parameter_key(int(match[1]))
    match = _CODE.fullmatch(compact)
    if match:
        code = int(match[1], 16)
        item = BY_CODE.get(code)
        if item is not None:
            return instruction_key(item)
        if is_paged(code):
            offset = code & 0x7F
            raise UsageError(
                f"H{code:02X} is a parameter code: it means Pr.{offset}, Pr.1{offset:02d} … "
                f"depending on the link-parameter page; write the parameter, e.g. Pr.{offset}"
            )
        raise UsageError(f"H{code:02X} is not an instruction code this codec knows")
    raise UsageError(
        f"{text[:20]!r} is neither a parameter (Pr.7, 7) nor an instruction code (H7A)"
    )


def resolve(key: ParameterKey) -> Instruction | ParameterSpec:
    """What a key (made by :func:`parse_parameter`) addresses; UsageError if it is foreign."""
    if key.code >= INSTRUCTION_KEY_BASE:
        item = BY_CODE.get(key.code - INSTRUCTION_KEY_BASE)
        if item is not None and item.key_name == key.name:
            return item
    elif 0 <= key.code <= MAX_PARAMETER and key.name == f"Pr.{key.code}":
        return lookup(key.code)
    raise UsageError(f"{key.name} is not a Mitsubishi parameter key")


def read_widths(key: ParameterKey) -> tuple[int, ...]:
    """Data widths a read reply for ``key`` may have."""
    target = resolve(key)
    return PARAMETER_DIGITS if isinstance(target, ParameterSpec) else target.read_widths


def key_value(key: ParameterKey, raw: int, text: str | None = None) -> ParameterValue:
    """The value ``raw`` data (or the model-name ``text``) of ``key`` stands for."""
    target = resolve(key)
    if text is not None:
        return ParameterValue(
            parameter=key, index=0, raw=None, value=text.rstrip(), unit="", title=target.name
        )
    value = target.to_value(raw) if isinstance(target, ParameterSpec) else item_value(target, raw)
    return ParameterValue(
        parameter=key, index=0, raw=raw, value=value, unit=target.unit, title=target.name
    )


# -- parameter sets (fcmaster.protocol.parameter_set) ------------------------------------

# A set is every parameter of the table (Pr.0-Pr.899 are settings), in number order.
SET_MEMBERS: Final = tuple((f"Pr.{n}", s.name) for n, s in sorted(PARAMETERS.items()))
IDENTITY: Final = (("H7C", "model name"),)
IDENTITY_MATCH: Final = frozenset({"H7C"})
# With Pr.77 = 0 (factory) a link write is accepted only while stopped (§8); the manuals'
# list of parameters writable during operation was not at hand, so none is taken as such.
CHANGEABLE_WHILE_RUNNING: Final[frozenset[str]] = frozenset()
# Station number, speed, format, parity, waiting time, terminator, protocol, and the
# operation mode (Pr.79): changing any of them mid-restore cuts this master off the drive.
LINK_SETTINGS: Final = frozenset(
    f"Pr.{n}" for n in (79, 117, 118, 119, 120, 123, 124, 331, 332, 333, 334, 337, 341, 549)
)
FREQUENCY_CEILINGS: Final = frozenset({"Pr.1", "Pr.18"})  # maximum, high-speed maximum
SET_RANGES: Final[tuple[tuple[str, float, float], ...]] = ()  # none taken from the manuals yet
