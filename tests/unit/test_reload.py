"""What a reload applies: the running config and the new one compared."""

from __future__ import annotations

from fcmaster.config import Config, parse
from fcmaster.reload import compare, config_hash

BASE = """
buses:
  - name: north
    port: /dev/ttyUSB0
    baudrate: 19200
    drives:
      - {{name: pump-1, address: 1, control: bus}}
{north}
  - name: south
    port: /dev/ttyUSB1
    baudrate: {south_baud}
    drives:
      - {{name: fan-1, address: 5}}
http:
  listen: 127.0.0.1:{http}
modbus: {{listen: 127.0.0.1:5020}}
on_shutdown: {on_shutdown}
"""


def config(
    *, north: str = "", south_baud: int = 19200, http: int = 8080, on_shutdown: str = "hold"
) -> Config:
    return parse(
        BASE.format(north=north, south_baud=south_baud, http=http, on_shutdown=on_shutdown)
    )


def test_a_drive_added_to_a_line_keeps_its_port_and_restarts_only_the_modbus_map() -> None:
    old, new = config(), config(north="      - {name: pump-2, address: 2}")
    changes = compare(old, new)
    assert [line.name for line in changes.replan] == ["north"]
    assert (changes.reopen, changes.open, changes.close) == ([], [], [])
    assert changes.restart == ["modbus"]  # its register map is the drives'
    assert changes.described == [
        "north: drive pump-2 added",
        "modbus: restarted (the drives changed)",
    ]
    assert config_hash(old) != config_hash(new)
    assert config_hash(old) == config_hash(config())


def test_a_line_whose_settings_changed_reopens_alone() -> None:
    changes = compare(config(), config(south_baud=38400))
    assert [line.name for line in changes.reopen] == ["south"]
    assert (changes.replan, changes.restart) == ([], [])
    assert changes.described == ["south: line reopened (baudrate changed)"]


def test_a_removed_bus_drive_is_named_as_leaving_and_the_listener_restarts_alone() -> None:
    old = config(north="      - {name: pump-2, address: 2, control: bus}")
    new = config(http=8181, on_shutdown="stop")
    changes = compare(old, new)
    assert [(bus, drive.name) for bus, drive in changes.leaving] == [("north", "pump-2")]
    assert changes.restart == ["http", "modbus"]
    assert "http: restarted (http.listen changed)" in changes.described
    assert "on_shutdown: stop" in changes.described


def test_the_same_file_again_changes_nothing() -> None:
    changes = compare(config(), config())
    assert changes.described == []
    assert (changes.replan, changes.reopen, changes.restart, changes.leaving) == ([], [], [], [])
