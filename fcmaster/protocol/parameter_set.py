"""A drive's parameter set: what a backup holds, how two sets differ, what a restore may write.

Vendor-neutral. Which parameters make up a set, which say who the drive is, which may change
while the motor turns and which decide how the drive hears the master come from each vendor's
``parameters`` module (``SET_MEMBERS``, ``IDENTITY``, ``IDENTITY_MATCH``,
``CHANGEABLE_WHILE_RUNNING``, ``LINK_SETTINGS``), which its protocol spec hands on
(``ProtocolSpec.parameters``); this module only combines them.

A set travels as a plain mapping (YAML on disk, JSON over HTTP)::

    format: fcmaster-parameter-set/1
    protocol: danfoss-fc
    address: 1
    identity: {"15-40": {name: FC Type, value: FC-302}, …}
    parameters:
      "3-41": {name: Ramp 1 Ramp Up Time, value: 3.0, unit: s, raw: 300}
      "8-36": {name: …, refused: {code: 0, text: …}}   # the drive would not say

Values are compared by ``raw`` (the integer on the wire) where both sides have one, so a
rounding of the scaled value never hides or invents a difference.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final

from fcmaster.errors import UsageError
from fcmaster.protocol.codec import DriveError, ParameterValue
from fcmaster.protocol.registry import PROTOCOLS

FORMAT: Final = "fcmaster-parameter-set/1"


@dataclass(slots=True, frozen=True, kw_only=True)
class SetProfile:
    """What one protocol's parameter set is made of (names as the codec writes them)."""

    protocol: str
    members: tuple[tuple[str, str], ...]  # (parameter, name) in the order to read and write
    identity: tuple[tuple[str, str], ...]  # (parameter, name): who the drive is
    identity_match: frozenset[str]  # identity entries a restore insists on (type, model)
    changeable_while_running: frozenset[str]  # known from the manuals; all others: stopped
    link_settings: frozenset[str]  # address, baud, parity, protocol: never restored
    frequency_ceilings: frozenset[str] = frozenset()  # Hz settings capping the output
    ranges: tuple[tuple[str, float, float], ...] = ()  # (parameter, low, high) in its unit


def profile_for(protocol: str, source: object = None, profile: object = None) -> SetProfile:
    """The set profile of ``protocol``; UsageError for one this project does not know.

    Where a protocol's drives follow drive profiles (modbus-rtu), the set is the drive's
    ``profile``'s, else that of the profile the line's options (``source``) name.
    """
    spec = PROTOCOLS.get(protocol)
    if spec is None:
        raise UsageError(f"no parameter sets for protocol {protocol!r}")
    tables = spec.parameters_of(source, profile)
    return SetProfile(
        protocol=protocol,
        members=tables.set_members,
        identity=tables.identity,
        identity_match=tables.identity_match,
        changeable_while_running=tables.changeable_while_running,
        link_settings=tables.link_settings,
        frequency_ceilings=tables.frequency_ceilings,
        ranges=tables.ranges,
    )


@dataclass(slots=True, frozen=True, kw_only=True)
class Entry:
    """One parameter of a set: its value, or the drive's refusal to give it."""

    name: str = ""
    value: float | str | None = None
    unit: str = ""
    raw: int | None = None
    refused: DriveError | None = None

    @classmethod
    def of(cls, name: str, got: ParameterValue | DriveError) -> Entry:
        """The entry for what a read brought back."""
        if isinstance(got, DriveError):
            return cls(name=name, refused=got)
        return cls(name=name, value=got.value, unit=got.unit, raw=got.raw)

    def same_as(self, other: Entry) -> bool:
        """Whether both hold the same setting (refusals are equal to nothing)."""
        if self.refused is not None or other.refused is not None:
            return False
        if self.raw is not None and other.raw is not None:
            return self.raw == other.raw
        return self.value == other.value

    def shown(self) -> str:
        """``3.0 s``, ``FC-302``, or ``refused (error 0: …)``."""
        if self.refused is not None:
            return f"refused (error {self.refused.code}: {self.refused.text})"
        value = f"{self.value:g}" if isinstance(self.value, float) else str(self.value)
        return f"{value} {self.unit}".rstrip()

    def to_dict(self) -> dict[str, Any]:
        """The entry as the file writes it."""
        out: dict[str, Any] = {"name": self.name}
        if self.refused is not None:
            out["refused"] = {"code": self.refused.code, "text": self.refused.text}
            return out
        out["value"] = self.value
        if self.unit:
            out["unit"] = self.unit
        if self.raw is not None:
            out["raw"] = self.raw
        return out


@dataclass(slots=True, kw_only=True)
class ParameterSet:
    """A drive's identity and parameters, as read at one time."""

    protocol: str
    address: int
    identity: dict[str, Entry] = field(default_factory=dict)
    parameters: dict[str, Entry] = field(default_factory=dict)
    saved_at: str = ""

    def to_dict(self) -> dict[str, Any]:
        """The set as a file or an HTTP body holds it."""
        return {
            "format": FORMAT,
            "protocol": self.protocol,
            "address": self.address,
            "saved_at": self.saved_at,
            "identity": {k: e.to_dict() for k, e in self.identity.items()},
            "parameters": {k: e.to_dict() for k, e in self.parameters.items()},
        }

    @classmethod
    def from_dict(cls, data: object, *, source: str = "the set") -> ParameterSet:
        """Read a set back; UsageError naming every problem at once."""
        problems: list[str] = []
        if not isinstance(data, Mapping):
            raise UsageError(f"{source} is not a parameter set (a mapping with 'parameters')")
        if data.get("format") != FORMAT:
            problems.append(f"format: expected {FORMAT!r}, got {data.get('format')!r}")
        protocol = data.get("protocol")
        if not isinstance(protocol, str):
            problems.append("protocol: missing")
            protocol = ""
        else:
            try:
                profile_for(protocol)
            except UsageError as exc:
                problems.append(f"protocol: {exc}")
        address = data.get("address")
        if not isinstance(address, int) or isinstance(address, bool):
            problems.append("address: missing or not a whole number")
            address = -1
        identity = _entries(data.get("identity", {}), "identity", problems)
        parameters = _entries(data.get("parameters"), "parameters", problems)
        if problems:
            raise UsageError(f"{source} is not a valid parameter set: " + "; ".join(problems))
        saved_at = data.get("saved_at")
        return cls(
            protocol=protocol,
            address=address,
            identity=identity,
            parameters=parameters,
            saved_at=saved_at if isinstance(saved_at, str) else "",
        )


def _entries(raw: object, where: str, problems: list[str]) -> dict[str, Entry]:
    if not isinstance(raw, Mapping):
        problems.append(f"{where}: missing or not a mapping")
        return {}
    out: dict[str, Entry] = {}
    for key, item in raw.items():
        at = f"{where}.{key}"
        if not isinstance(item, Mapping):
            problems.append(f"{at}: not a mapping")
            continue
        name = item.get("name", "")
        refused = item.get("refused")
        if refused is not None:
            code = refused.get("code") if isinstance(refused, Mapping) else None
            if not isinstance(code, int):
                problems.append(f"{at}.refused: needs a whole-number 'code'")
                continue
            out[str(key)] = Entry(
                name=str(name), refused=DriveError(code, str(refused.get("text", "")))
            )
            continue
        value, raw_value, unit = item.get("value"), item.get("raw"), item.get("unit", "")
        if isinstance(value, bool) or not isinstance(value, int | float | str):
            problems.append(f"{at}.value: missing or not a number or text")
            continue
        if isinstance(value, float) and not math.isfinite(value):
            problems.append(f"{at}.value: {value} is not a finite number")
            continue
        if raw_value is not None and (
            isinstance(raw_value, bool) or not isinstance(raw_value, int)
        ):
            problems.append(f"{at}.raw: not a whole number")
            continue
        number = float(value) if isinstance(value, int) else value
        out[str(key)] = Entry(name=str(name), value=number, unit=str(unit), raw=raw_value)
    return out


@dataclass(slots=True, frozen=True, kw_only=True)
class Difference:
    """One parameter whose setting differs (None: absent from that side)."""

    parameter: str
    name: str
    left: Entry | None
    right: Entry | None

    def to_dict(self) -> dict[str, Any]:
        """The difference as JSON: each side's entry or null."""
        return {
            "parameter": self.parameter,
            "name": self.name,
            "left": None if self.left is None else self.left.to_dict(),
            "right": None if self.right is None else self.right.to_dict(),
        }


def compare(left: ParameterSet, right: ParameterSet) -> list[Difference]:
    """The parameters whose settings differ, in ``left``'s order then ``right``'s extras.

    Identity is not compared: two drives of one type always differ in serial number, and a
    set is about settings. Sets of different protocols cannot be compared (UsageError).
    """
    if left.protocol != right.protocol:
        raise UsageError(f"cannot compare a {left.protocol} set with a {right.protocol} set")
    out: list[Difference] = []
    for key in [*left.parameters, *(k for k in right.parameters if k not in left.parameters)]:
        a, b = left.parameters.get(key), right.parameters.get(key)
        if a is not None and b is not None and a.same_as(b):
            continue
        out.append(Difference(parameter=key, name=(a or b or Entry()).name, left=a, right=b))
    return out


def identity_mismatches(profile: SetProfile, saved: ParameterSet, drive: ParameterSet) -> list[str]:
    """Why ``saved`` was not taken from a drive like ``drive`` (empty: it may be restored)."""
    if saved.protocol != drive.protocol:
        return [f"the file is a {saved.protocol} set; the drive speaks {drive.protocol}"]
    out = []
    for key in sorted(profile.identity_match):
        a, b = saved.identity.get(key), drive.identity.get(key)
        if a is not None and b is not None and not a.same_as(b):
            out.append(f"{key} ({a.name}): the file says {a.shown()}, the drive {b.shown()}")
    return out


@dataclass(slots=True, frozen=True, kw_only=True)
class Verdict:
    """A restore's file judged as a whole, before anything is written.

    ``refused``: what no restore writes, forced or not (a parameter outside the set, such as
    FC 14-22 Operation Mode, whose "initialise" resets the drive at its next power-up; a
    value that cannot be sent). ``beyond_limits``: a frequency ceiling above the drive's
    configured ``max_frequency_hz``, written only when forced.
    """

    refused: tuple[str, ...] = ()
    beyond_limits: tuple[str, ...] = ()


def judge(
    profile: SetProfile,
    saved: ParameterSet,
    encode: Callable[[str, float], object],
    *,
    max_frequency_hz: float | None = None,
) -> Verdict:
    """Every parameter of ``saved`` judged as a restore would write it.

    ``encode`` builds the write of a value without sending it and raises UsageError for one
    the parameter cannot take (beyond its type's range, below zero, not finite); a value
    outside the range the manual gives (``SetProfile.ranges``) is refused too. A line
    setting or an entry the drive refused to read is never written, so only its membership
    is judged. ``max_frequency_hz``: the drive's configured limit, when known.
    """
    members = dict(profile.members)
    ranges = {key: (low, high) for key, low, high in profile.ranges}
    refused: list[str] = []
    beyond: list[str] = []
    for key, entry in saved.parameters.items():
        label = f"{key} ({members.get(key) or entry.name or 'unnamed'})"
        if key not in members:
            refused.append(f"{label}: not in the {profile.protocol} parameter set, and a "
                           "restore writes only the set's own parameters")  # fmt: skip
            continue
        if entry.refused is not None or key in profile.link_settings:
            continue
        if not isinstance(entry.value, float):
            refused.append(f"{label}: {entry.value!r} is not a number")
            continue
        try:
            encode(key, entry.value)
        except UsageError as exc:
            refused.append(f"{label} = {entry.shown()}: cannot be written ({exc})")
            continue
        low, high = ranges.get(key, (-math.inf, math.inf))
        if not low <= entry.value <= high:
            refused.append(f"{label} = {entry.shown()}: outside {low:g}-{high:g} "
                           f"{entry.unit}".rstrip())  # fmt: skip
            continue
        ceiling = max_frequency_hz
        if ceiling is not None and key in profile.frequency_ceilings and entry.value > ceiling:
            beyond.append(f"{label} = {entry.shown()} is above the drive's configured "
                          f"max_frequency_hz {ceiling:g}")  # fmt: skip
    return Verdict(refused=tuple(refused), beyond_limits=tuple(beyond))


Reader = Callable[[str], Awaitable[ParameterValue | DriveError]]


async def read_set(
    profile: SetProfile,
    address: int,
    read: Reader,
    *,
    saved_at: str = "",
    on_progress: Callable[[int, int, str], None] | None = None,
) -> ParameterSet:
    """Read the identity and every member through ``read`` (which raises on silence)."""
    out = ParameterSet(protocol=profile.protocol, address=address, saved_at=saved_at)
    todo = [*((k, n, out.identity) for k, n in profile.identity),
            *((k, n, out.parameters) for k, n in profile.members)]  # fmt: skip
    for done, (key, name, into) in enumerate(todo, 1):
        into[key] = Entry.of(name, await read(key))
        if on_progress is not None:
            on_progress(done, len(todo), key)
    return out
