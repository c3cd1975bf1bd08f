"""The modbus section and per-drive unit ids."""

from __future__ import annotations

import pytest

from fcmaster.config import parse
from fcmaster.errors import ConfigError

TWO_LINES = """
buses:
  - name: line1
    port: sim://line1
    drives: [{name: pump-1, address: 1}, {name: pump-2, address: 2}]
  - name: line2
    port: sim://line2
    drives: [{name: fan-1, address: 1}]
"""


def problems(text: str) -> list[tuple[str, str]]:
    with pytest.raises(ConfigError) as info:
        parse(text)
    return info.value.problems


def test_without_a_modbus_section_equal_addresses_on_two_lines_are_fine() -> None:
    assert parse(TWO_LINES).model.modbus is None


def test_with_modbus_a_unit_id_used_twice_names_both_drives_and_the_fix() -> None:
    ((path, reason),) = problems(TWO_LINES + "modbus: {}\n")
    assert path == "buses[1].drives[0].modbus_unit"
    assert "pump-1 (buses[0].drives[0].address)" in reason
    assert "modbus_unit" in reason
    fixed = TWO_LINES.replace(
        "{name: fan-1, address: 1}", "{name: fan-1, address: 1, modbus_unit: 11}"
    )
    model = parse(fixed + "modbus: {}\n").model.modbus
    assert model is not None
    assert (model.listen, model.allow, model.commands) == ("127.0.0.1:5020", None, False)


def test_a_modbus_unit_outside_1_247_and_a_station_0_are_refused() -> None:
    text = TWO_LINES.replace("address: 2}", "address: 2, modbus_unit: 248}")
    assert problems(text)[0][0] == "buses[0].drives[1].modbus_unit"
    station0 = """
buses:
  - {name: line1, port: sim://a, protocol: mitsubishi, drives: [{name: m0, address: 0}]}
modbus: {}
"""
    ((path, reason),) = problems(station0)
    assert path == "buses[0].drives[0].modbus_unit"
    assert "set modbus_unit" in reason


def test_listening_beyond_loopback_needs_an_allow_list_and_bad_networks_are_named() -> None:
    ((path, reason),) = problems(TWO_LINES.replace("address: 1}]\n", "address: 11}]\n", 1)
                                 + "modbus: {listen: 0.0.0.0:502}\n")  # fmt: skip
    assert path == "modbus.listen"
    assert "modbus.allow" in reason
    text = TWO_LINES.replace("{name: fan-1, address: 1}", "{name: fan-1, address: 3}")
    assert parse(text + "modbus: {listen: 0.0.0.0:502, allow: [10.0.5.0/24]}\n").model.modbus
    assert problems(text + "modbus: {listen: 0.0.0.0:502, allow: []}\n")[0][0] == "modbus.listen"
    found = problems(text + "modbus: {listen: '10.0.0.1', allow: [10.0.0.0/8, 10.0.0.300]}\n")
    assert [p for p, _ in found] == ["modbus.listen", "modbus.allow[1]"]


@pytest.mark.parametrize("listen", ["[::1]:5020", "localhost:5020", "127.0.0.2:502"])
def test_loopback_listen_addresses_need_no_allow_list(listen: str) -> None:
    text = TWO_LINES.replace("{name: fan-1, address: 1}", "{name: fan-1, address: 3}")
    model = parse(text + f'modbus: {{listen: "{listen}"}}\n').model.modbus
    assert model is not None
    assert model.listen == listen


@pytest.mark.parametrize("listen", ["127.0.0.1", "127.0.0.1:x", ":5020", "127.0.0.1:70000"])
def test_a_listen_address_without_a_usable_port_is_refused(listen: str) -> None:
    text = TWO_LINES.replace("{name: fan-1, address: 1}", "{name: fan-1, address: 3}")
    found = problems(text + f'modbus: {{listen: "{listen}"}}\n')
    assert found[0][0] == "modbus.listen"
