"""The simulated Mitsubishi drive's parameters: ranges, factory settings and the store.

Increments and units come from the codec's table (:data:`fcmaster.protocol.mitsubishi.
PARAMETERS`), so the simulator and the master scale values alike. This module adds what
only a drive knows: each parameter's range, whether 9999 (or 8888) is one of its settings,
its factory value, and whether it may change while the motor turns. Values are kept raw,
in setting increments, as they travel (9999 as HFFFF, 8888 as HFFFE).

Ranges are the 700-series ones as far as protocols/mitsubishi.md gives them (Pr.117-Pr.124,
Pr.549); the others are plausible FR-E700 figures. One setting differs from the factory on
purpose: Pr.340 (communication start-up mode) is 1, so a simulated drive starts in network
operation, as a commissioned drive on a bus does; with the factory 0 it would refuse every
run command with a mode error until something wrote HFB.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.mitsubishi.parameters import (
    SETTING_8888,
    SETTING_9999,
    lookup,
    parse_parameter,
    resolve,
)
from fcmaster.protocol.mitsubishi.parameters import ParameterSpec as CodecSpec


@dataclass(slots=True, frozen=True, kw_only=True)
class Setting:
    """A parameter as the drive keeps it: raw range, special settings, factory value."""

    number: int
    default: int  # raw
    low: int = 0
    high: int = 9998
    with_9999: bool = False  # 9999 (HFFFF) is a setting of its own ("off", "from the frame")
    with_8888: bool = False
    stopped_only: bool = True  # Pr.77 = 0: writes only while stopped (§8)

    @property
    def spec(self) -> CodecSpec:
        """The codec's view: increment and unit."""
        return lookup(self.number)

    def accepts(self, raw: int) -> bool:
        """Whether ``raw`` is a setting of this parameter."""
        if raw == SETTING_9999:
            return self.with_9999
        if raw == SETTING_8888:
            return self.with_8888
        return self.low <= raw <= self.high


def _s(number: int, default: int, low: int, high: int, **kwargs: bool) -> Setting:
    return Setting(number=number, default=default, low=low, high=high, **kwargs)


# raw values: Pr.1 12000 = 120.00 Hz, Pr.7 50 = 5.0 s, Pr.122 in 0.1 s, …
SETTINGS: Final[dict[int, Setting]] = {
    s.number: s
    for s in (
        _s(0, 60, 0, 300),  # torque boost, 0.1 %
        _s(1, 12000, 0, 12000),  # maximum frequency
        _s(2, 0, 0, 12000),  # minimum frequency
        _s(3, 5000, 0, 40000),  # base frequency
        _s(4, 5000, 0, 40000, stopped_only=False),
        _s(5, 3000, 0, 40000, stopped_only=False),
        _s(6, 1000, 0, 40000, stopped_only=False),
        _s(7, 50, 0, 36000, stopped_only=False),  # acceleration time, 0.1 s
        _s(8, 50, 0, 36000, stopped_only=False),  # deceleration time, 0.1 s
        _s(9, 1100, 0, 50000),  # electronic thermal O/L relay, 0.01 A
        _s(13, 50, 0, 6000),  # starting frequency
        _s(15, 500, 0, 40000, stopped_only=False),  # jog frequency
        _s(16, 5, 0, 36000, stopped_only=False),
        _s(18, 12000, 12000, 40000),  # high speed maximum frequency
        _s(20, 5000, 100, 40000),  # acceleration/deceleration reference frequency
        _s(77, 0, 0, 2, stopped_only=False),
        _s(78, 0, 0, 2),
        _s(79, 0, 0, 7),
        _s(117, 0, 0, 31),
        _s(118, 192, 48, 384),
        _s(119, 1, 0, 11),
        _s(120, 2, 0, 2),
        _s(121, 1, 0, 10, with_9999=True),
        _s(122, SETTING_9999, 0, 9998, with_9999=True),  # 0.1 s; 9999 = no check (sim factory)
        _s(123, SETTING_9999, 0, 150, with_9999=True),  # ms; 9999 = the digit travels in requests
        _s(124, 1, 0, 2),
        _s(335, 1, 0, 10, with_9999=True),  # as Pr.121, for the RS-485 terminals
        _s(336, SETTING_9999, 0, 9998, with_9999=True),  # as Pr.122, for the RS-485 terminals
        _s(338, 0, 0, 1),
        _s(339, 0, 0, 2),
        _s(340, 1, 0, 10),  # see the module docstring
        _s(342, 0, 0, 1),
        _s(549, 0, 0, 2),
    )
}
WAIT_STEP_MS: Final = 10  # Pr.123 takes 0-150 ms in steps of 10 (§1.1)
COMMUNICATION: Final = frozenset(range(117, 125)) | {335, 336, 549}  # kept by "clear except comm"


class ParameterStore:
    """Current raw values, with what was written to EEPROM kept apart from RAM."""

    def __init__(self, overrides: Mapping[int, int] | None = None) -> None:
        """Factory settings, then ``overrides`` (number → raw); UsageError for a bad one."""
        self._values = {number: s.default for number, s in SETTINGS.items()}
        for number, raw in (overrides or {}).items():
            setting = SETTINGS.get(number)
            if setting is None or not setting.accepts(raw):
                raise UsageError(f"Pr.{number}: {raw} is not a setting the simulator knows")
            self._values[number] = raw

    def __getitem__(self, number: int) -> int:
        return self._values[number]

    def set(self, number: int, raw: int) -> None:
        """Store a checked value."""
        self._values[number] = raw

    def value(self, number: int) -> float:
        """The value in the parameter's unit (9999 as itself)."""
        return SETTINGS[number].spec.to_value(self._values[number])

    def clear(self, *, keep_communication: bool) -> None:
        """Parameter clear (HFC): back to the factory settings."""
        for number, setting in SETTINGS.items():
            if not (keep_communication and number in COMMUNICATION):
                self._values[number] = setting.default


def overrides_from_values(values: Mapping[str, float]) -> dict[int, int]:
    """``{"Pr.7": 2.5, "122": 1.0}`` → raw overrides; UsageError for a name or value."""
    out: dict[int, int] = {}
    for name, value in values.items():
        key = parse_parameter(name)
        target = resolve(key)
        if not isinstance(target, CodecSpec) or target.number not in SETTINGS:
            raise UsageError(f"{name} is not a parameter the simulated drive has")
        out[target.number] = target.to_raw(value)
    return out
