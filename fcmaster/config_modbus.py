"""The ``modbus`` section's checks that need the whole file: unit ids, and who may connect.

A unit id names one drive across every bus, so it is checked over all the buses at once;
Modbus has no authentication, so listening beyond this machine needs an ``allow`` list.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from fcmaster.adapters.settings import modbus_listen
from fcmaster.config_sections import ModbusModel, is_loopback

__all__ = ["check_modbus", "modbus_units"]


class _Drive(Protocol):
    @property
    def name(self) -> str: ...
    @property
    def address(self) -> int: ...
    @property
    def modbus_unit(self) -> int | None: ...


class _Bus(Protocol):
    @property
    def drives(self) -> Sequence[_Drive]: ...


def modbus_units(buses: Sequence[_Bus], problems: list[tuple[str, str]]) -> dict[str, int]:
    """Each drive's Modbus unit id (``modbus_unit``, else its bus address), by drive name.

    A unit id names one drive across every bus, so a clash (two lines that both have an
    address 1) is a problem for ``problems``, with the fix.
    """
    units: dict[str, int] = {}
    seen: dict[int, str] = {}
    for b, bus in enumerate(buses):
        for d, drive in enumerate(bus.drives):
            where = f"buses[{b}].drives[{d}]"
            unit = drive.address if drive.modbus_unit is None else drive.modbus_unit
            if not 1 <= unit <= 247:
                problems.append(
                    (
                        f"{where}.modbus_unit",
                        f"address {unit} is no Modbus unit id (1-247): set modbus_unit",
                    )
                )
                continue
            key = f"{where}.modbus_unit" if drive.modbus_unit is not None else f"{where}.address"
            if unit in seen:
                problems.append(
                    (
                        f"{where}.modbus_unit",
                        f"Modbus unit {unit} is already taken by {seen[unit]}: set a "
                        "modbus_unit of its own on one of them",
                    )
                )
                continue
            seen[unit] = f"{drive.name} ({key})"
            units[drive.name] = unit
    return units


def check_modbus(
    modbus: ModbusModel, buses: Sequence[_Bus], problems: list[tuple[str, str]]
) -> None:
    """Add to ``problems`` what is wrong with ``modbus`` given the drives of ``buses``."""
    modbus_units(buses, problems)
    host, _ = modbus_listen(modbus.listen)
    if not modbus.allow and not is_loopback(host):  # [] lets no PLC in either
        problems.append(
            (
                "modbus.listen",
                f"{modbus.listen} reaches beyond this machine and Modbus has no "
                "authentication: list the PLCs' addresses in modbus.allow "
                "(e.g. [10.0.5.0/24]) or listen on 127.0.0.1",
            )
        )
