"""The vendor-neutral motor model: ramps, stops, measured values and lazy integration."""

from __future__ import annotations

import pytest

from fcmaster.sim import Mode, Motor, MotorCommand, MotorRating

RATED = MotorRating()  # 5.5 kW, 400 V, 50 Hz, 11 A, 1450 rpm


def run(target_hz: float, **ramps: float) -> MotorCommand:
    return MotorCommand(mode=Mode.RUN, target_hz=target_hz, **ramps)


def test_ramp_up_time_is_from_zero_to_rated_frequency() -> None:
    motor = Motor(RATED, 0.0)
    motor.set_command(run(25.0, ramp_up_s=3.0), 0.0)
    motor.advance(0.75)
    assert motor.frequency_hz == pytest.approx(12.5)
    assert motor.is_ramping
    motor.advance(1.5)
    assert motor.frequency_hz == 25.0
    assert not motor.is_ramping


def test_reversing_decelerates_through_zero_then_accelerates() -> None:
    motor = Motor(RATED, 0.0)
    motor.set_command(run(50.0, ramp_up_s=0.0), 0.0)
    motor.advance(0.0)
    assert motor.frequency_hz == 50.0
    motor.set_command(run(-50.0, ramp_up_s=1.0, ramp_down_s=2.0), 0.0)
    motor.advance(2.0)
    assert motor.frequency_hz == pytest.approx(0.0)
    motor.advance(2.5)
    assert motor.frequency_hz == pytest.approx(-25.0)
    motor.advance(10.0)
    assert motor.frequency_hz == -50.0


def test_stop_ramps_down_then_switches_off_and_notes_when() -> None:
    motor = Motor(RATED, 0.0)
    motor.set_command(run(50.0, ramp_up_s=0.0), 0.0)
    motor.set_command(MotorCommand(mode=Mode.STOP, ramp_down_s=2.0), 1.0)
    motor.advance(2.0)
    assert motor.frequency_hz == pytest.approx(25.0)
    assert motor.output_on
    motor.advance(5.0)
    assert not motor.output_on
    assert motor.frequency_hz == 0.0
    assert motor.zero_at == pytest.approx(3.0)
    assert motor.current_a == 0.0
    assert motor.voltage_v == 0.0


def test_quick_stop_uses_its_own_ramp_and_off_is_immediate() -> None:
    motor = Motor(RATED, 0.0)
    motor.set_command(run(50.0, ramp_up_s=0.0), 0.0)
    motor.set_command(MotorCommand(mode=Mode.QUICK_STOP, ramp_down_s=9.0, quick_stop_s=0.5), 1.0)
    motor.advance(1.5)
    assert not motor.output_on
    motor.set_command(run(50.0, ramp_up_s=0.0), 2.0)
    motor.set_command(MotorCommand(mode=Mode.OFF), 2.0)
    assert motor.frequency_hz == 0.0
    assert not motor.output_on


def test_hold_keeps_the_present_frequency() -> None:
    motor = Motor(RATED, 0.0)
    motor.set_command(run(50.0, ramp_up_s=5.0), 0.0)
    motor.set_command(MotorCommand(mode=Mode.HOLD, target_hz=50.0), 1.0)
    motor.advance(100.0)
    assert motor.frequency_hz == pytest.approx(10.0)


def test_rated_load_at_rated_frequency_draws_rated_current_and_voltage() -> None:
    motor = Motor(RATED, 0.0, load=1.0)
    motor.set_command(run(50.0, ramp_up_s=0.0), 0.0)
    motor.advance(1.0)
    assert motor.current_a == pytest.approx(11.0)
    assert motor.voltage_v == pytest.approx(400.0)
    assert motor.power_kw == pytest.approx(5.5 / 0.95)
    assert motor.speed_rpm == pytest.approx(1450.0)
    assert motor.torque_fraction == pytest.approx(1.0)
    assert 500 < motor.dc_link_v < 566


def test_measured_values_move_with_speed_and_load() -> None:
    motor = Motor(RATED, 0.0, load=0.5)
    motor.set_command(run(25.0, ramp_up_s=0.0), 0.0)
    motor.advance(1.0)
    half = (motor.current_a, motor.voltage_v, motor.power_kw)
    motor.set_command(run(50.0, ramp_up_s=0.0), 1.0)
    motor.advance(2.0)
    assert motor.voltage_v == pytest.approx(2 * half[1])
    assert motor.current_a > half[0]
    assert motor.power_kw > 4 * half[2]
    motor.set_load(1.0, 2.0)
    assert motor.current_a > 8.0
    motor.set_command(run(50.0, ramp_up_s=10.0), 3.0)
    ramping = Motor(RATED, 0.0, load=0.5)
    ramping.set_command(run(50.0, ramp_up_s=10.0), 0.0)
    ramping.advance(9.0)
    assert ramping.torque_fraction > Motor(RATED, 0.0).torque_fraction  # accelerating torque


def test_counters_and_temperatures_integrate_over_time() -> None:
    motor = Motor(RATED, 0.0, load=1.0)
    motor.set_command(run(50.0, ramp_up_s=0.0), 0.0)
    motor.advance(7200.0)
    assert motor.running_s == pytest.approx(7200.0)
    assert motor.energy_kwh == pytest.approx(2 * 5.5 / 0.95, rel=1e-3)
    assert motor.heatsink_c == pytest.approx(30.0 + 5.0 + 40.0, abs=0.1)
    motor.set_command(MotorCommand(mode=Mode.OFF), 7200.0)
    motor.advance(9000.0)
    assert motor.operating_s == pytest.approx(9000.0)
    assert motor.running_s == pytest.approx(7200.0)
    assert motor.heatsink_c < 40.0


def test_lazy_integration_does_not_depend_on_how_often_it_is_asked() -> None:
    once, often = Motor(RATED, 0.0), Motor(RATED, 0.0)
    for motor in (once, often):
        motor.set_command(run(50.0, ramp_up_s=20.0), 0.0)
    once.advance(30.0)
    for i in range(1, 3001):
        often.advance(i * 0.01)
    assert once.frequency_hz == often.frequency_hz == 50.0
    assert once.energy_kwh == pytest.approx(often.energy_kwh, rel=1e-3)
    assert once.heatsink_c == pytest.approx(often.heatsink_c, rel=1e-3)


def test_time_never_runs_backwards() -> None:
    motor = Motor(RATED, 10.0)
    motor.set_command(run(50.0, ramp_up_s=1.0), 10.0)
    motor.advance(10.5)
    motor.advance(5.0)
    assert motor.frequency_hz == pytest.approx(25.0)
    assert motor.updated_at == 10.5


def test_an_interlocked_motor_hears_a_run_command_and_stays_off() -> None:
    motor = Motor(RATED, 0.0)
    motor.interlocked = True
    motor.set_command(run(25.0, ramp_up_s=1.0), 0.0)
    motor.advance(2.0)
    assert motor.frequency_hz == 0.0
    assert not motor.output_on
