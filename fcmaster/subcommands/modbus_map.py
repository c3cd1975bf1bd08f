"""`fcmaster modbus-map`: the Modbus TCP register map of a config, for PLC programmers."""

from __future__ import annotations

import json
from pathlib import Path

from fcmaster import config as config_module
from fcmaster.adapters.modbus_map import ACTIONS, register_map


def run(path: Path, *, as_json: bool) -> int:
    """Print the map of ``path``'s drives (JSON: one object per value)."""
    # The map needs the buses and the modbus section, never the HTTP or MQTT secrets.
    config = config_module.load(path, buses_only=True)
    mapping = register_map(config.lines, config.modbus_units())
    if as_json:
        print(json.dumps(mapping.entries(), indent=2, ensure_ascii=False))
        return 0
    settings = config.modbus
    if settings is None:
        print("modbus: no such section in this config: the server is off (this is its map)")
    else:
        access = "commands on" if settings.commands else "read-only (modbus.commands: false)"
        print(f"modbus: {settings.listen}, {access}")
    print(
        "Addresses count from 0 as on the wire; a PLC or SCADA that counts from 1 adds 1\n"
        "(input register 0 = 30001, holding register 0 = 40001). 32-bit values put the\n"
        "high word first. value = register × scale. Unknown values (drive offline, not read\n"
        "yet) read 0xFFFF (u16), 0x80000000 (i32) or NaN (f32); online and age_s tell why.\n"
        f"command codes: {', '.join(f'{code} {name}' for code, name in ACTIONS.items())}."
    )
    for unit in mapping.units.values():
        drive = unit.drive
        control = "control: bus" if drive.control else "monitor-only"
        print(
            f"\nunit {unit.unit_id}: {drive.name} ({unit.bus}, address {drive.address}, {control})"
        )
        print(f"  {'table':<8}{'address':>7}  {'name':<22}{'type':<6}{'scale':<7}unit")
        for register in (*unit.inputs, *unit.holdings):
            print(
                f"  {register.table:<8}{register.address:>7}  {register.name:<22}"
                f"{register.type:<6}{register.scale:<7g}{register.unit}".rstrip()
            )
    return 0
