"""What the meaning pass can still check of a bus or drive that failed validation.

A bus or drive with a wrong key is kept with that key left out: at its default, or at a
stand-in where the key is required (:func:`mend`). Its other keys are then checked as in a
good file, so a baud rate typo does not hide an address out of range beside it. A check
that reads a key left out would judge a value the user never wrote, so its problems are
not believed (:class:`Dropped`): a missing ``protocol`` makes every address check moot, a
dropped ``max_frequency_hz`` the minimum's.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from fcmaster.protocol.registry import line_keys

__all__ = ["STAND_INS", "Dropped", "mend"]

_Model = TypeVar("_Model", bound=BaseModel)

# What a required key that fails stands at: the checks that read it are not believed, and
# these collide with nothing a user writes (a negative address is in no protocol's range).
STAND_INS: dict[str, Any] = {"name": "(not a valid name)", "port": "(not a valid port)"}
_DRIVE_STAND_INS: dict[str, Any] = {**STAND_INS, "address": -1}


def mend(model: type[_Model], value: Any, *, drive: bool) -> tuple[_Model, frozenset[str]] | None:
    """``value`` validated as ``model`` with the keys that fail left out, and those keys.

    None: it cannot be mended (not a mapping, or a problem that is not of one key).
    """
    if not isinstance(value, dict):
        return None
    try:
        return model.model_validate(value), frozenset()
    except ValidationError as exc:
        errors = exc.errors()
    bad = set()
    for error in errors:
        loc = error["loc"]
        if not loc or not isinstance(loc[0], str):
            return None
        bad.add(loc[0])
    stand_ins = _DRIVE_STAND_INS if drive else STAND_INS
    rest = {key: item for key, item in value.items() if key not in bad}
    rest |= {key: stand_ins[key] for key in bad if key in stand_ins}
    try:
        return model.model_validate(rest), frozenset(bad)
    except ValidationError:
        return None


# The keys a protocol's checks depend on: the protocol and its own line keys
# (address_format, the Modbus line's profile, …).
_PROTOCOL_KEYS = frozenset({"protocol"} | {key.name for key, _ in line_keys()})
_FREQUENCIES = frozenset({"min_frequency_hz", "max_frequency_hz", "nominal_frequency_hz"})
# buses[b], .drives[d], then a key and the key under it: monitor[2], watchdog.timeout_s
_PATH = re.compile(r"buses\[(\d+)\](?:\.drives\[(\d+)\])?(?:\.(\w+))?(?:\[\d+\])?(?:\.(\w+))?.*")


@dataclass(slots=True)
class Dropped:
    """The keys left out of each kept bus and drive, indexed as the partial model has them."""

    buses: list[frozenset[str]] = field(default_factory=list)
    drives: list[list[frozenset[str]]] = field(default_factory=list)
    names: list[str] = field(default_factory=list)  # each kept bus's name, as checked
    # per kept bus: whether its address range could differ with the keys left out written
    addresses_moot: list[bool] = field(default_factory=list)
    # per kept bus: which of its drives have no profile key of their own
    unprofiled: list[list[bool]] = field(default_factory=list)

    def add_bus(
        self,
        bus: Any,  # a config.BusModel (that module imports this one)
        left_out: frozenset[str],
        drives: list[frozenset[str]],
        *,
        addresses_moot: bool,
    ) -> None:
        """One more bus kept, with what was left out of it and of each of its drives."""
        self.names.append(bus.name)
        self.buses.append(left_out)
        self.drives.append(drives)
        self.addresses_moot.append(addresses_moot)
        self.unprofiled.append([drive.profile is None for drive in bus.drives])

    def believed(self, path: str) -> bool:
        """Whether the meaning pass's problem at ``path`` read only keys the user wrote."""
        for b, name in enumerate(self.names):
            if path.startswith(f"buses.{name}."):  # the simulated line: built of every key
                return not self._any(b, but=frozenset())
        match = _PATH.fullmatch(path)
        if match is None:
            return not path.startswith("buses")  # the other sections are checked whole
        b = int(match[1])
        bus = self.buses[b]
        if match[2] is None:
            key = match[3]
            if key in ("name", "port"):
                return key not in bus
            return not bus & {"protocol", key}  # baudrate, or a key of another protocol
        drive, key = self.drives[b][int(match[2])], match[3]
        if key == "name":
            return "name" not in drive
        d = int(match[2])
        if key == "address":
            return key not in drive and not self.addresses_moot[b]
        if key == "profile":  # the line's profile serves a drive without one of its own
            line = {"protocol", "profile"} if self.unprofiled[b][d] else {"protocol"}
            return key not in drive and not bus & line
        if key == "monitor":
            return key not in drive and not bus & _PROTOCOL_KEYS
        if key == "min_frequency_hz":
            return not drive & _FREQUENCIES
        if key == "modbus_unit":  # unit ids are compared across every bus
            units = {"address", "modbus_unit"}
            return not any(other & units for drives in self.drives for other in drives)
        if key == "watchdog":
            wrote = not drive & {"watchdog", "control", "profile"} and not bus & _PROTOCOL_KEYS
            if match[4] != "timeout_s":
                return wrote
            # also judged against the line's poll round: the line's keys, what each drive polls
            polled = {"monitor", "profile", "address"}
            return (
                wrote and not bus - STAND_INS.keys() and not any(d & polled for d in self.drives[b])
            )
        return not self._any(b)

    def _any(self, b: int, *, but: frozenset[str] = frozenset({"name"})) -> bool:
        """Whether anything (``but`` these keys) was left out of bus ``b`` or its drives."""
        return bool(self.buses[b] - but) or any(d - but for d in self.drives[b])
