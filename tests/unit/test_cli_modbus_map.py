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
