"""A Modbus drive's parameter set (``fcmaster params``): what its drive profile lists.

Modbus itself names no parameters, so a backup of a Modbus drive holds what its profile
lists as settings (``DriveProfile.parameters``), then its communication watchdog's
registers, each under the register's name as the codec writes it (``hr512``,
``hr8029x2``). A drive without a profile has no set. Nothing here tells a register that
sets how the drive talks on the line (none is listed), or one that may change while the
motor turns, so a restore writes each one only while the drive reports it stopped.
"""

from __future__ import annotations

from typing import Final

from fcmaster.errors import UsageError
from fcmaster.protocol.codec import ParameterKey
from fcmaster.protocol.modbus_rtu.keys import key_register, register_key
from fcmaster.protocol.modbus_rtu.profile import DriveProfile
from fcmaster.protocol.modbus_rtu.replies import scaled, title_of
from fcmaster.protocol.spec import ParameterTables

_WATCHDOG_NAMES: Final = {
    "timeout": "Communication watchdog timeout",
    "action": "Communication watchdog action",
    "enable": "Communication watchdog enable",
}


def members(profile: DriveProfile) -> tuple[tuple[str, str], ...]:
    """(parameter, name) of the set, in the order a backup reads them."""
    listed = [(register_key(v.register).name, v.name) for v in profile.parameters]
    watchdog = profile.watchdog
    for part, name in _WATCHDOG_NAMES.items():
        register = getattr(watchdog, part)
        if register is not None:
            listed.append((register_key(register).name, name))
    kept: dict[str, str] = {}
    for key, name in listed:  # a register listed twice is one member, by its first name
        kept.setdefault(key, name)
    return tuple(kept.items())


def tables_of(profile: DriveProfile | None) -> ParameterTables:
    """The set tables of a drive following ``profile`` (empty without one)."""

    def unit_of(key: ParameterKey) -> str:
        try:
            register = key_register(key)
        except UsageError:  # a profile's own key (output frequency, fault)
            return ""
        return scaled(profile, register).unit

    return ParameterTables(
        set_members=() if profile is None else members(profile),
        identity=(),
        identity_match=frozenset(),
        changeable_while_running=frozenset(),
        link_settings=frozenset(),
        unit_of=unit_of,
        title_of=lambda key: title_of(profile, key),
    )
