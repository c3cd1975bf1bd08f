"""The register map: where each value sits, how it is encoded, what unknown looks like."""

from __future__ import annotations

import dataclasses
import math
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.adapters.modbus import EXCEPTION_OF
from fcmaster.adapters.modbus_frames import ExceptionCode
from fcmaster.adapters.modbus_map import Register, RegisterMap, register_map
from fcmaster.bus.commands import Outcome
from fcmaster.config import parse
from fcmaster.errors import ConfigError
from fcmaster.state import DriveState, Measured

CONFIG = """
buses:
  - name: line1
    port: sim://line1
    drives:
      - {name: pump-1, address: 1, control: bus, nominal_frequency_hz: 60,
         monitor: ["16-14", "16-90"]}
  - name: line2
    port: sim://line2
    protocol: mitsubishi
    drives:
      - {name: fan-1, address: 1, modbus_unit: 21}
"""


def _map(text: str) -> RegisterMap:
    """The register map of the config ``text``, unit ids as the config gives them."""
    config = parse(text)
    return register_map(config.lines, config.modbus_units())


def test_every_unit_has_the_state_block_then_its_monitored_values() -> None:
    entries = _map(CONFIG).entries()
    pump = [e for e in entries if e["unit_id"] == 1]
    assert [(e["table"], e["address"], e["name"], e["type"]) for e in pump[:3]] == [
        ("input", 0, "online", "u16"),
        ("input", 1, "age_s", "u16"),
        ("input", 2, "status_word", "u16"),
    ]
    values = [(e["address"], e["name"], e["type"], e["unit"]) for e in pump if e["address"] >= 16]
    assert values[:4] == [
        (16, "16-14", "f32", "A"),
        (18, "16-14.raw", "i32", ""),
        (20, "16-90", "f32", ""),
        (22, "16-90.raw", "i32", ""),
    ]
    holding = [
        (e["address"], e["name"], e["scale"], e["unit"]) for e in pump if e["table"] == "holding"
    ]
    assert holding == [(0, "command", 1.0, ""), (1, "reference_hz", 0.01, "Hz")]
    fan = [e for e in entries if e["unit_id"] == 21]
    assert {e["drive"] for e in fan} == {"fan-1"}
    # Mitsubishi's default monitor: output frequency, current and voltage (H6F, H70, H71)
    assert [(e["name"], e["unit"]) for e in fan if e["type"] == "f32"] == [
        ("H6F", "Hz"),
        ("H70", "A"),
        ("H71", "V"),
    ]


def test_two_drives_on_one_unit_id_are_refused_with_the_keys() -> None:
    clash = CONFIG.replace(", modbus_unit: 21", "")
    with pytest.raises(ConfigError) as info:
        _map(clash)
    ((path, reason),) = info.value.problems
    assert path == "buses[1].drives[0].modbus_unit"
    assert "pump-1 (buses[0].drives[0].address)" in reason


ONLINE = DriveState(
    name="pump-1", bus="line1", address=1, protocol="danfoss-fc", control="bus", online=True,
    running=True, status_word=0x0F07, output_frequency_hz=42.5, reference_pct=75.0,
    values={"16-14": Measured(12.5, "A", 125), "16-90": Measured(float(1 << 31), "", 1 << 31)},
    updated_at=1000.0,
)  # fmt: skip


def words(state: DriveState, now: float = 1001.25) -> list[int]:
    unit = _map(CONFIG).units[1]
    return unit.words("input", state, now)


def test_values_are_scaled_and_32_bit_ones_put_the_high_word_first() -> None:
    w = words(ONLINE)
    assert w[0:4] == [1, 12, 0x0F07, 1]  # online, 1.25 s → 12 tenths, status, running
    assert w[8:10] == [4250, 7500]
    assert struct.unpack(">f", struct.pack(">HH", *w[16:18]))[0] == 12.5
    assert w[18:20] == [0, 125]
    assert w[22:24] == [0x8000, 0x0000]  # bit 31 of an alarm word: the bits as sent
    holding = _map(CONFIG).units[1].words("holding", ONLINE, 0.0)
    assert holding == [0, 4500]  # 75 % of 60 Hz


def test_an_offline_drive_shows_only_online_and_age_others_unknown() -> None:
    w = words(dataclasses.replace(ONLINE, online=False), now=1100.0)
    assert w[0:2] == [0, 1000]
    assert w[2:14] == [0xFFFF] * 12
    assert math.isnan(struct.unpack(">f", struct.pack(">HH", *w[16:18]))[0])
    assert w[18:20] == [0x8000, 0]


def test_what_does_not_fit_its_register_reads_unknown_never_clipped() -> None:
    w = words(dataclasses.replace(ONLINE, output_frequency_hz=700.0, updated_at=None))
    assert w[8] == 0xFFFF  # 700 Hz does not fit 0.01 Hz in 16 bits
    assert w[1] == 0xFFFF  # never answered: age unknown


def test_every_outcome_has_the_exception_design_maps_it_to() -> None:
    assert {o.value for o in Outcome} - {"done"} <= set(EXCEPTION_OF)
    assert EXCEPTION_OF["superseded"] == EXCEPTION_OF["unconfirmed"] == ExceptionCode(4)
    assert (EXCEPTION_OF["timeout"], EXCEPTION_OF["cancelled"]) == (0x0B, 0x0A)


def test_a_float_beyond_float32_reads_nan() -> None:
    state = dataclasses.replace(ONLINE, values={"16-14": Measured(1e40, "A", 1)})
    assert math.isnan(struct.unpack(">f", struct.pack(">HH", *words(state)[16:18]))[0])


@given(st.integers(0, 0xFFFE), st.sampled_from([0, 1, 2]))
def test_a_u16_value_comes_back_from_its_register(raw: int, decimals: int) -> None:
    register = Register(table="input", address=0, name="x", type="u16", decimals=decimals,
                        read=lambda _s, _n: None)  # fmt: skip
    (word,) = register.encode(raw / 10**decimals)
    assert word == raw


@given(st.integers(-0x7FFFFFFF, 0x7FFFFFFF))
def test_an_i32_is_its_twos_complement_high_word_first(value: int) -> None:
    register = Register(table="input", address=0, name="x", type="i32", read=lambda _s, _n: None)
    high, low = register.encode(value)
    assert struct.unpack(">i", struct.pack(">HH", high, low))[0] == value
