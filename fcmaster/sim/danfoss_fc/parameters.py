"""The simulated FC drive's settable parameters: ranges, options, defaults and the store.

Data types and scaling come from the codec's table (:data:`fcmaster.protocol.danfoss_fc.
PARAMETERS`), so the simulator and the master agree by construction. This module adds what
only a drive knows: each writable parameter's range or option list, its factory setting,
and whether it may be changed while the motor turns. Values are kept raw (the integers on
the wire); ``value()`` scales them.

Ranges follow the FC 301/302 programming guide where protocols/danfoss-fc.md gives them
(8-03, 8-35…8-37) and plausible FC 302 figures elsewhere. Two settings differ from the
factory on purpose: 4-14 Motor Speed High Limit defaults to 65 Hz, above 3-03 Maximum
Reference (50 Hz), so a drive at full reference is not at its speed limit.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

from fcmaster.errors import FcmasterError, UsageError
from fcmaster.protocol.danfoss_fc.error_codes import LIMIT_EXCEEDED
from fcmaster.protocol.danfoss_fc.parameters import (
    PARAMETERS,
    DataType,
    ParameterSpec,
    format_parameter,
    parse_parameter,
)

# 8-32 FC Port Baud Rate options, in the order the manuals list them [U]
BAUD_OPTIONS: Final = (2400, 4800, 9600, 19200, 38400, 57600, 76800, 115200)
# 8-33 Parity / Stop Bits options: (parity, stop bits) → option
PARITY_OPTIONS: Final = {("E", 1): 0, ("O", 1): 1, ("N", 1): 2, ("N", 2): 3}
TIMEOUT_FUNCTIONS: Final = frozenset({0, 1, 2, 3, 4, 5, 7, 8, 9, 10})  # 8-04, FC 102 list

_INT32: Final = 999_999_999


class Refused(FcmasterError):
    """A parameter access the drive answers with AK 7 and ``code``."""

    def __init__(self, code: int, message: str = "") -> None:
        self.code = code
        super().__init__(message or f"refused with error {code}")


@dataclass(slots=True, frozen=True, kw_only=True)
class Setting:
    """A writable parameter as the drive sees it."""

    spec: ParameterSpec
    default: int  # raw
    low: int = 0
    high: int = 0
    options: frozenset[int] | None = None  # an option list instead of a range
    stopped_only: bool = False  # refused with error 17 while the motor turns
    at_least: int | None = None  # PNU whose value is a lower bound
    at_most: int | None = None  # PNU whose value is an upper bound


def _spec(number: str, name: str, data_type: DataType, conversion: int, unit: str) -> ParameterSpec:
    return ParameterSpec(pnu=parse_parameter(number), name=name, data_type=data_type,
                         conversion=conversion, unit=unit, writable=True)  # fmt: skip


# Motor name-plate data (group 1-2*): not in the codec's table, which the master reads by
# the reply's width; the simulator needs their types to answer.
MOTOR_SPECS: Final = {
    spec.pnu: spec
    for spec in (
        _spec("1-20", "Motor Power [kW]", DataType.UINT32, 1, "kW"),
        _spec("1-22", "Motor Voltage", DataType.UINT16, 0, "V"),
        _spec("1-23", "Motor Frequency", DataType.UINT16, 0, "Hz"),
        _spec("1-24", "Motor Current", DataType.UINT32, -2, "A"),
        _spec("1-25", "Motor Nominal Speed", DataType.UINT16, 67, "rpm"),
    )
}


def _s(number: str, default: int, low: int = 0, high: int = 0, *,
       options: frozenset[int] | None = None, stopped_only: bool = False,
       at_least: str | None = None, at_most: str | None = None) -> Setting:  # fmt: skip
    pnu = parse_parameter(number)
    return Setting(
        spec=MOTOR_SPECS.get(pnu) or PARAMETERS[pnu], default=default, low=low, high=high,
        options=options, stopped_only=stopped_only,
        at_least=None if at_least is None else parse_parameter(at_least),
        at_most=None if at_most is None else parse_parameter(at_most),
    )  # fmt: skip


SETTINGS: Final[dict[int, Setting]] = {
    setting.spec.pnu: setting
    for setting in (
        _s("1-20", 550, 9, 100_000, stopped_only=True),  # 5.50 kW
        _s("1-22", 400, 10, 1000, stopped_only=True),
        _s("1-23", 50, 20, 1000, stopped_only=True),
        _s("1-24", 1100, 1, 1_000_000, stopped_only=True),  # 11.00 A
        _s("1-25", 1450, 100, 60_000, stopped_only=True),
        _s("3-02", 0, -_INT32, _INT32, at_most="3-03"),
        _s("3-03", 50_000, -_INT32, _INT32, at_least="3-02"),  # 50.000 Hz
        _s("3-19", 100, 0, 5900, at_most="4-14"),  # 10.0 Hz
        _s("3-41", 300, 1, 360_000),  # 3.00 s
        _s("3-42", 300, 1, 360_000),
        _s("3-51", 300, 1, 360_000),
        _s("3-52", 300, 1, 360_000),
        _s("3-81", 300, 1, 360_000),
        _s("4-12", 0, 0, 5900, at_most="4-14"),
        _s("4-14", 650, 0, 5900, at_least="4-12"),  # 65.0 Hz
        _s("8-03", 10, 1, 180_000),  # 1.0 s
        _s("8-04", 0, options=TIMEOUT_FUNCTIONS),
        _s("8-30", 0, options=frozenset({0, 1, 2})),
        _s("8-31", 1, 1, 126),
        _s("8-32", 2, options=frozenset(range(len(BAUD_OPTIONS)))),
        _s("8-33", 0, options=frozenset(PARITY_OPTIONS.values())),
        _s("8-35", 10, 5, 10_000),  # ms
        _s("8-36", 10_001, 11, 10_001),  # ms
        _s("8-37", 2500, 0, 3500),  # 0.01 ms
    )
}


class ParameterStore:
    """The raw values of one drive's writable parameters."""

    def __init__(self, overrides: Mapping[int, int] | None = None) -> None:
        """Factory settings, then ``overrides`` (PNU → raw), each checked like a bus write."""
        self._values = {pnu: setting.default for pnu, setting in SETTINGS.items()}
        overrides = overrides or {}
        for pnu, raw in overrides.items():
            if pnu not in SETTINGS:
                raise UsageError(f"parameter {format_parameter(pnu)} cannot be set")
            self._values[pnu] = raw
        for pnu, raw in overrides.items():  # after all are in: bounds may depend on each other
            try:
                self.check(pnu, raw)
            except Refused as exc:
                raise UsageError(f"parameter {format_parameter(pnu)} = {raw}: {exc}") from None

    def __getitem__(self, pnu: int) -> int:
        return self._values[pnu]

    def value(self, pnu: int) -> float:
        """The value of ``pnu`` in its unit (3-41 raw 300 → 3.0 s)."""
        return SETTINGS[pnu].spec.to_value(self._values[pnu])

    def check(self, pnu: int, raw: int) -> None:
        """Raise :class:`Refused` (error 2) if ``raw`` is outside the range or options."""
        setting = SETTINGS[pnu]
        if setting.options is not None:
            if raw not in setting.options:
                raise Refused(LIMIT_EXCEEDED, f"option {raw} does not exist")
            return
        low = setting.low if setting.at_least is None else max(setting.low, self[setting.at_least])
        high = setting.high if setting.at_most is None else min(setting.high, self[setting.at_most])
        if not low <= raw <= high:
            raise Refused(LIMIT_EXCEEDED, f"{raw} is outside {low}…{high}")

    def set(self, pnu: int, raw: int) -> None:
        """Store ``raw`` after :meth:`check`."""
        self.check(pnu, raw)
        self._values[pnu] = raw


def overrides_from_values(values: Mapping[str, float]) -> dict[int, int]:
    """``{"3-41": 5.0}`` (engineering units, the manual's notation) → ``{341: 500}`` raw."""
    out = {}
    for number, value in values.items():
        pnu = parse_parameter(number)
        setting = SETTINGS.get(pnu)
        if setting is None:
            raise UsageError(f"parameter {number} cannot be set on a simulated FC drive")
        out[pnu] = setting.spec.to_raw(value)
    return out
