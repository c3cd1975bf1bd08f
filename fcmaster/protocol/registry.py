"""The protocols this master speaks: one line per protocol, and the lookups by name.

A protocol is a package under ``fcmaster/protocol/`` with a ``spec.py`` (see
:mod:`fcmaster.protocol.spec`), plus its simulated drives under ``fcmaster/sim/``; it is
switched on by its line below. The first line is the default of every ``--protocol`` and of
a bus without a ``protocol`` key.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING, Any, Final

from fcmaster.errors import UsageError

if TYPE_CHECKING:
    from fcmaster.protocol.spec import LineKey, ProtocolSpec

# A protocol's name and the module whose ``SPEC`` describes it. A spec is imported the first
# time it is asked for, so what needs only the names (a LinePlan's default, the choices of
# --protocol) does not load every codec.
_SPEC_MODULES: Final = {
    "danfoss-fc": "fcmaster.protocol.danfoss_fc.spec",
    "mitsubishi": "fcmaster.protocol.mitsubishi.spec",
    "enc": "fcmaster.protocol.enc.spec",
    "modbus-rtu": "fcmaster.protocol.modbus_rtu.spec",
}
NAMES: Final = tuple(_SPEC_MODULES)  # in registry order: the choices of --protocol
DEFAULT: Final = NAMES[0]


class _Specs(Mapping[str, "ProtocolSpec[Any]"]):
    """Every protocol's spec by name, in registry order, each imported on first use."""

    def __getitem__(self, name: str) -> ProtocolSpec[Any]:
        spec: ProtocolSpec[Any] = importlib.import_module(_SPEC_MODULES[name]).SPEC
        if spec.name != name:
            raise ImportError(f"{_SPEC_MODULES[name]}.SPEC is named {spec.name!r}, not {name!r}")
        return spec

    def __iter__(self) -> Iterator[str]:
        return iter(NAMES)

    def __len__(self) -> int:
        return len(NAMES)


PROTOCOLS: Final[Mapping[str, ProtocolSpec[Any]]] = _Specs()


def spec_for(name: str) -> ProtocolSpec[Any]:
    """The spec of protocol ``name``; UsageError naming the known ones if there is none."""
    if name not in _SPEC_MODULES:
        known = ", ".join(NAMES)
        raise UsageError(f"protocol {name!r} is not supported (have: {known})")
    return PROTOCOLS[name]


def line_keys() -> tuple[tuple[LineKey, ProtocolSpec[Any]], ...]:
    """Every protocol's own line keys with the protocol that has each, in registry order."""
    return tuple((key, spec) for spec in PROTOCOLS.values() for key in spec.line_keys)
