"""`fcmaster modbus-map`: the map a PLC programmer works from."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fcmaster.cli import main

CONFIG = """
buses:
  - name: line1
    port: /dev/ttyUSB0
    drives:
      - {name: pump-1, address: 1, control: bus, monitor: ["16-14"]}
  - name: line2
    port: /dev/ttyUSB1
    drives:
      - {name: pump-9, address: 1}
modbus: {commands: true}
"""


def test_json_lists_every_register_with_its_unit_id_and_drive(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "fleet.yaml"
    path.write_text(CONFIG.replace("address: 1}\nmodbus", "address: 1, modbus_unit: 9}\nmodbus"))
    assert main(["modbus-map", "--config", str(path), "--json"]) == 0
    entries = json.loads(capsys.readouterr().out)
    keys = {"unit_id", "bus", "drive", "table", "address", "name", "type", "scale", "unit"}
    assert all(set(e) == keys for e in entries)
    current = next(e for e in entries if e["unit_id"] == 1 and e["name"] == "16-14")
    assert current == {
        "unit_id": 1, "bus": "line1", "drive": "pump-1", "table": "input", "address": 16,
        "name": "16-14", "type": "f32", "scale": 1.0, "unit": "A",
    }  # fmt: skip
    assert {e["drive"] for e in entries if e["unit_id"] == 9} == {"pump-9"}


def test_the_text_map_and_a_clash_of_unit_ids(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "fleet.yaml"
    path.write_text(CONFIG.replace("address: 1}\nmodbus", "address: 2}\nmodbus"))
    assert main(["modbus-map", "--config", str(path)]) == 0
    out = capsys.readouterr().out
    assert "unit 1: pump-1 (line1, address 1, control: bus)" in out
    assert "  holding       1  reference_hz          u16   0.01   Hz" in out
    path.write_text(CONFIG)  # both drives at address 1, no modbus_unit
    assert main(["modbus-map", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "buses[1].drives[0].modbus_unit" in err


MODBUS_RTU = """
buses:
  - name: rtu
    port: /dev/ttyUSB0
    protocol: modbus-rtu
    drives:
      - {name: abb, address: 1, profile: abb-drives}
      - {name: yaskawa, address: 4, profile: yaskawa-memobus}
      - {name: altivar, address: 3, profile: altivar-cia402, monitor: ["ir3204", "hr3207"]}
modbus: {}
"""


def test_a_modbus_rtu_drives_values_carry_its_profiles_names_units_and_registers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "fleet.yaml"
    path.write_text(MODBUS_RTU)
    assert main(["modbus-map", "--config", str(path), "--json"]) == 0
    entries = json.loads(capsys.readouterr().out)

    def values(unit_id: int) -> list[tuple[str, str, str]]:
        return [
            (e["name"], e["type"], e["unit"])
            for e in entries
            if e["unit_id"] == unit_id and e["table"] == "input" and e["address"] >= 16
        ]

    # each drive its own profile's values (not every profile's on the line), with units
    assert values(1) == [
        ("hr106", "f32", "A"), ("hr106.raw", "i32", ""),
        ("hr109", "f32", "%"), ("hr109.raw", "i32", ""),
        ("hr110", "f32", "V"), ("hr110.raw", "i32", ""),
    ]  # fmt: skip
    assert values(4) == [
        ("hr38", "f32", "A"), ("hr38.raw", "i32", ""),
        ("hr49", "f32", "V"), ("hr49.raw", "i32", ""),
    ]  # fmt: skip
    # a monitor list names registers; one the profile lists is in its unit (hr3207 is the
    # profile's mains voltage; ir3204 is not listed as an input register: no unit)
    assert values(3) == [
        ("ir3204", "f32", ""), ("ir3204.raw", "i32", ""),
        ("hr3207", "f32", "V"), ("hr3207.raw", "i32", ""),
    ]  # fmt: skip
