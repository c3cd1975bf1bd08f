"""sim:// lines built from a bus's config, as the daemon's service asks for them."""

from __future__ import annotations

from typing import Any

import pytest

from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.errors import ConfigError
from fcmaster.protocol.danfoss_fc import decode_reference, decode_telegram, encode_telegram
from fcmaster.sim import FcSimDrive
from fcmaster.sim.service import sim_line, sim_transport
from tests.fakes import FakeClock
from tests.unit.sim.wire import REF_50, START, control, transact

PLAN = LinePlan(
    name="line1", port="sim://line1", baudrate=38400, parity="N", response_delay_s=0.005,
    drives=(
        DrivePlan(name="pump", address=3, nominal_frequency_hz=60.0, max_frequency_hz=60.0),
        DrivePlan(name="fan", address=7),
    ),
)  # fmt: skip


def fc(line: Any, address: int) -> FcSimDrive:
    found = next(d for d in line.drives if d.address == address)
    assert isinstance(found, FcSimDrive)
    return found


def test_one_drive_per_configured_address_in_the_bus_format() -> None:
    clock = FakeClock()
    line = sim_line(PLAN, {}, clock=clock)
    assert sorted(d.address for d in line.drives) == [3, 7]
    assert line.char_bits == 10
    assert line.baudrate == 38400
    assert all(d.response_delay_s == 0.005 for d in line.drives)


def test_100_percent_reference_is_the_drive_nominal_frequency() -> None:
    clock = FakeClock()
    line = sim_line(PLAN, {}, clock=clock)
    transact(line, clock, control(3, START, REF_50))
    clock.time += 10.0
    reply = decode_telegram(transact(line, clock, control(3, START, REF_50)), from_drive=True)
    assert decode_reference(reply.pcd2) == 50.0
    assert fc(line, 3).motor.frequency_hz == pytest.approx(30.0)


def test_simulation_section_sets_faults_load_and_parameters() -> None:
    clock = FakeClock()
    simulation = {
        "seed": 4, "faults": "corrupt=0.5", "load": 0.3, "response_delay_ms": 12,
        "drives": {"7": {"load": 0.9, "faults": {"drop": 1.0}, "parameters": {"3-41": 1.5},
                         "local": True},
                   "3": {"interlocked": True}},
    }  # fmt: skip
    transport = sim_transport(PLAN, simulation, clock=clock)
    line = transport.line
    assert transport.port == "sim://line1"
    assert line.faults.corrupt == 0.5
    assert line.faults.seed == 4
    assert (fc(line, 3).motor.load, fc(line, 7).motor.load) == (0.3, 0.9)
    assert fc(line, 7).parameters.value(341) == 1.5
    assert fc(line, 7).control.local
    assert fc(line, 3).motor.interlocked
    assert not fc(line, 7).motor.interlocked
    assert fc(line, 3).response_delay_s == 0.012
    line.write(encode_telegram(control(7, START)))
    assert line.next_delivery() is None  # drive 7 drops every reply


def test_echo_on_the_bus_makes_the_line_echo() -> None:
    plan = LinePlan(name="l", port="sim://l", echo=True, drives=(DrivePlan(name="d", address=1),))
    assert sim_line(plan, {}, clock=FakeClock()).faults.echo


@pytest.mark.parametrize(
    ("simulation", "path"),
    [
        ({"speed": 1}, "buses.line1.simulation.speed"),
        ({"faults": "drop=7"}, "buses.line1.simulation.faults"),
        ({"faults": 3}, "buses.line1.simulation.faults"),
        ({"drives": {"9": {}}}, "buses.line1.simulation.drives"),
        ({"drives": {"3": {"color": "red"}}}, "buses.line1.simulation.drives.3.color"),
        ({"drives": {"3": {"load": "heavy"}}}, "buses.line1.simulation.drives.3"),
        ({"drives": {"3": {"parameters": {"16-13": 1}}}}, "buses.line1.simulation"),
        ({"drives": [1, 2]}, "buses.line1.simulation.drives"),
    ],
)
def test_mistakes_name_their_key_path(simulation: dict[str, Any], path: str) -> None:
    with pytest.raises(ConfigError) as caught:
        sim_line(PLAN, simulation, clock=FakeClock())
    assert caught.value.problems[0][0] == path
