"""The protocols this master speaks: one line per protocol, and the lookups by name.

A protocol is a package under ``fcmaster/protocol/`` with a ``spec.py`` (see
:mod:`fcmaster.protocol.spec`), plus its simulated drives under ``fcmaster/sim/``; it is
switched on by its line below. The first line is the default of every ``--protocol`` and of
a bus without a ``protocol`` key.
"""

from __future__ import annotations

from typing import Any, Final

from fcmaster.errors import UsageError
from fcmaster.protocol.danfoss_fc.spec import SPEC as DANFOSS_FC
from fcmaster.protocol.enc.spec import SPEC as ENC
from fcmaster.protocol.mitsubishi.spec import SPEC as MITSUBISHI
from fcmaster.protocol.spec import LineKey, ProtocolSpec

PROTOCOLS: Final[dict[str, ProtocolSpec[Any]]] = {
    spec.name: spec
    for spec in (
        DANFOSS_FC,
        MITSUBISHI,
        ENC,
    )
}
NAMES: Final = tuple(PROTOCOLS)  # in registry order: the choices of --protocol
DEFAULT: Final = NAMES[0]


def spec_for(name: str) -> ProtocolSpec[Any]:
    """The spec of protocol ``name``; UsageError naming the known ones if there is none."""
    try:
        return PROTOCOLS[name]
    except KeyError:
        known = ", ".join(NAMES)
        raise UsageError(f"protocol {name!r} is not supported (have: {known})") from None


def line_keys() -> tuple[tuple[LineKey, ProtocolSpec[Any]], ...]:
    """Every protocol's own line keys with the protocol that has each, in registry order."""
    return tuple((key, spec) for spec in PROTOCOLS.values() for key in spec.line_keys)
