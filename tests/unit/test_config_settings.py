"""The config hands each adapter its settings: every key carried over, the defaults the same."""

from __future__ import annotations

import pytest

from fcmaster.adapters.settings import (
    HttpSettings,
    ModbusSettings,
    MqttSettings,
    TlsSettings,
    Token,
)
from fcmaster.config import HttpModel, ModbusModel, MqttModel, parse
from fcmaster.errors import ConfigError

BUSES = """
buses:
  - name: line1
    port: sim://line1
    drives:
      - {name: pump-1, address: 1, control: bus}
      - {name: pump-2, address: 2, modbus_unit: 40}
"""

FULL = (
    BUSES
    + """
http:
  listen: 0.0.0.0:8081
  anonymous: viewer
  cors_origins: [http://scada.example]
  tokens:
    - {name: ops, role: operator, token: operator-secret-0123456789}
mqtt:
  url: mqtts://broker.example:8884
  base_topic: plant/fc
  status_topic: plant/fc/gw1
  client_id: gw1
  username: fc
  password: pw
  tls: {insecure: true}
  heartbeat_s: 30
  deadband_pct: 1.5
  discovery: true
  discovery_prefix: ha
  keepalive_s: 15
  reconnect_min_s: 2
  reconnect_max_s: 20
  commands: true
  trust_broker: true
modbus:
  listen: 0.0.0.0:1502
  allow: [10.0.5.0/24]
  commands: true
"""
)


def test_every_key_of_each_section_reaches_its_adapters_settings() -> None:
    config = parse(FULL)
    assert config.http == HttpSettings(
        listen="0.0.0.0:8081",
        tokens=(Token("ops", "operator", "operator-secret-0123456789"),),
        anonymous="viewer",
        cors_origins=("http://scada.example",),
    )
    assert config.mqtt == MqttSettings(
        url="mqtts://broker.example:8884",
        base_topic="plant/fc",
        status_topic="plant/fc/gw1",
        client_id="gw1",
        username="fc",
        password="pw",
        tls=TlsSettings(insecure=True),
        heartbeat_s=30.0,
        deadband_pct=1.5,
        discovery=True,
        discovery_prefix="ha",
        keepalive_s=15,
        reconnect_min_s=2.0,
        reconnect_max_s=20.0,
        commands=True,
        trust_broker=True,
    )
    assert config.modbus == ModbusSettings(
        listen="0.0.0.0:1502",
        allow=("10.0.5.0/24",),
        commands=True,
        units={"pump-1": 1, "pump-2": 40},
    )


def test_an_absent_section_hands_down_nothing() -> None:
    config = parse(BUSES)
    assert (config.http, config.mqtt, config.modbus) == (None, None, None)


def test_a_sections_defaults_are_its_settings_defaults() -> None:
    # Tests and tools build settings from a few keys; they must mean what the file means.
    assert HttpModel().settings() == HttpSettings()
    assert MqttModel().settings() == MqttSettings()
    assert ModbusModel().settings({}) == ModbusSettings(units={})
    assert MqttSettings().commands is False  # commands stay off unless switched on
    assert ModbusSettings(units={}).commands is False


def test_unit_ids_of_a_file_without_a_modbus_section_are_checked_when_asked() -> None:
    second = BUSES.replace("buses:\n", "").replace("line1", "line2").replace("pump-", "fan-")
    config = parse(BUSES + second)  # no modbus section: a clash is no problem of the file
    with pytest.raises(ConfigError) as info:
        config.modbus_units()
    (first, first_reason), (other, other_reason) = info.value.problems
    assert (first, other) == ("buses[1].drives[0].modbus_unit", "buses[1].drives[1].modbus_unit")
    assert "pump-1 (buses[0].drives[0].address)" in first_reason
    assert "pump-2 (buses[0].drives[1].modbus_unit)" in other_reason
