"""The simulated FC drive obeys the control word as the FC profile says (§8)."""

from __future__ import annotations

import pytest

from fcmaster.protocol.danfoss_fc import StatusWord, decode_reference
from fcmaster.sim import DriveSettings, FcSimDrive, LineSettings, build_line
from tests.fakes import FakeClock
from tests.unit.sim.wire import (
    COAST,
    FREEZE,
    IGNORED,
    JOG,
    QUICK_STOP,
    RAMP_2,
    REF_50,
    REF_100,
    RESET,
    REVERSE,
    START,
    STOP,
    ask,
    control,
    drive,
    fc_line,
)

S = StatusWord
STOPPED = S.CONTROL_READY | S.DRIVE_READY | S.ENABLED | S.BUS_CONTROL | S.FREQUENCY_OK
RUNNING_AT_REFERENCE = STOPPED | S.RUNNING | S.AT_REFERENCE


class Bench:
    """One FC drive at address 1, driven by telegrams in virtual time."""

    def __init__(self, **parameters: float) -> None:
        self.clock = FakeClock()
        settings = DriveSettings(parameters={k.replace("_", "-"): v for k, v in parameters.items()})
        self.line = fc_line(self.clock, (1,), settings=settings)
        self.drive: FcSimDrive = drive(self.line, 1)

    def send(self, ctw: int, ref: int = REF_100) -> tuple[int, float]:
        """Status word and MAV % of the reply."""
        reply = ask(self.line, self.clock, control(1, ctw, ref))
        return reply.pcd1, decode_reference(reply.pcd2)

    def wait(self, seconds: float) -> None:
        self.clock.time += seconds

    def feed(self, seconds: float, ctw: int = START) -> None:
        """Keep sending ``ctw`` every 0.1 s for ``seconds``, as a master does."""
        end = self.clock.now() + seconds
        while self.clock.now() < end:
            self.send(ctw)
            self.wait(0.1)

    @property
    def hz(self) -> float:
        self.drive.advance(self.clock.now())
        return self.drive.motor.frequency_hz


def test_power_up_status_is_ready_and_stopped() -> None:
    bench = Bench()
    assert bench.send(IGNORED) == (STOPPED, 0.0)


def test_start_ramps_to_the_reference_and_the_status_follows() -> None:
    bench = Bench()  # 3-41 = 3 s from 0 to 50 Hz; 3-03 = 50 Hz is 100 %
    status, mav = bench.send(START, REF_50)
    assert status & S.RUNNING
    assert not status & S.AT_REFERENCE
    assert mav < 1.0
    bench.wait(0.75)
    status, mav = bench.send(START, REF_50)
    assert mav == pytest.approx(25.5, abs=0.5)
    assert not status & S.AT_REFERENCE
    bench.wait(1.0)
    assert bench.send(START, REF_50) == (RUNNING_AT_REFERENCE, 50.0)
    assert bench.hz == pytest.approx(25.0)


def test_ramp_stop_decelerates_with_the_ramp_down_time() -> None:
    bench = Bench(**{"3_42": 1.0})
    bench.send(START)
    bench.wait(5.0)
    bench.send(STOP)
    bench.wait(0.5)
    assert bench.hz == pytest.approx(25.0, abs=1.0)  # the reply's wire time counts too
    bench.wait(1.0)
    assert bench.send(STOP) == (STOPPED, 0.0)


def test_coast_switches_the_output_off_at_once_and_clears_enable() -> None:
    bench = Bench()
    bench.send(START)
    bench.wait(5.0)
    status, mav = bench.send(COAST)
    assert mav == 0.0
    assert not status & (S.RUNNING | S.ENABLED)
    assert status & S.DRIVE_READY


def test_quick_stop_uses_3_81() -> None:
    bench = Bench(**{"3_81": 0.5, "3_42": 10.0})
    bench.send(START)
    bench.wait(5.0)
    bench.send(QUICK_STOP)
    bench.wait(0.5)
    assert bench.hz == 0.0


def test_dc_brake_bit_low_stops() -> None:
    bench = Bench()
    bench.send(START)
    bench.wait(5.0)
    status, _ = bench.send(START & ~0x0004)
    assert not status & S.RUNNING


def test_freeze_holds_the_output_while_the_reference_changes() -> None:
    bench = Bench()
    bench.send(START, REF_50)
    bench.wait(5.0)
    bench.send(FREEZE, REF_100)
    bench.wait(5.0)
    assert bench.hz == pytest.approx(25.0)


def test_jog_runs_at_3_19_and_reverse_turns_the_other_way() -> None:
    bench = Bench(**{"3_19": 7.5})
    bench.send(JOG, 0)
    bench.wait(5.0)
    assert bench.hz == pytest.approx(7.5)
    bench.send(REVERSE, REF_50)
    bench.wait(10.0)
    assert bench.send(REVERSE, REF_50)[1] == -50.0
    assert bench.hz == pytest.approx(-25.0)


def test_bit_9_selects_ramp_2() -> None:
    bench = Bench(**{"3_51": 1.0, "3_41": 10.0})
    bench.send(RAMP_2)
    bench.wait(0.5)
    assert bench.hz == pytest.approx(25.0, abs=1.0)


def test_a_word_without_bit_10_is_ignored_with_its_reference() -> None:
    bench = Bench()
    bench.send(START & ~0x0400)  # start, but "data not valid"
    bench.wait(2.0)
    assert bench.hz == 0.0
    bench.send(START, REF_50)
    bench.wait(5.0)
    bench.send(IGNORED, 0)  # a monitor-only poll: 0x0000 with reference 0
    bench.send(0x043C & ~0x0400, 0)  # a stop word marked not valid
    bench.wait(5.0)
    assert bench.hz == pytest.approx(25.0)
    assert bench.drive.control.control_word == START


def test_over_current_trips_and_a_reset_edge_clears_it_once_the_cause_is_gone() -> None:
    bench = Bench()
    bench.send(START)
    bench.wait(5.0)
    bench.drive.control.raise_alarm(13, bench.clock.now())
    status, mav = bench.send(START)
    assert status & S.TRIP
    assert not status & (S.RUNNING | S.DRIVE_READY)
    assert mav == 0.0
    assert bench.drive.control.alarm_word == 1 << 5  # 16-90 bit 5: over current
    assert bench.send(RESET)[0] & S.TRIP  # an edge, but the cause is still present
    bench.drive.control.clear_alarm(13, bench.clock.now())
    assert bench.send(RESET)[0] & S.TRIP  # bit 7 was already 1: no edge
    bench.send(START)
    status, _ = bench.send(RESET)
    assert not status & S.TRIP
    assert bench.drive.control.alarm_log[0][0] == 13


def test_trip_lock_needs_a_power_cycle() -> None:
    bench = Bench()
    bench.drive.control.raise_alarm(14, bench.clock.now())  # earth fault
    bench.drive.control.clear_alarm(14, bench.clock.now())
    bench.send(STOP)
    status, _ = bench.send(RESET)
    assert status & S.TRIP_LOCK
    bench.drive.control.power_cycle(bench.clock.now())
    assert bench.send(IGNORED)[0] == STOPPED


def test_warnings_set_the_warning_bit_and_their_status_bits() -> None:
    bench = Bench()
    bench.drive.control.raise_warning(59, bench.clock.now())  # current limit
    status, _ = bench.send(IGNORED)
    assert status & S.WARNING
    assert status & S.TORQUE_EXCEEDED
    assert bench.drive.control.warning_word == 1 << 25
    bench.drive.control.clear_warning(59, bench.clock.now())
    assert bench.send(IGNORED)[0] == STOPPED


def test_a_drive_in_local_operation_ignores_the_bus() -> None:
    clock = FakeClock()
    line = build_line(LineSettings(), [(1, DriveSettings(local=True))], clock=clock)
    status = ask(line, clock, control(1, START, REF_100)).pcd1
    assert not status & (S.BUS_CONTROL | S.RUNNING)


def test_speed_limit_holds_the_output_and_clears_frequency_ok() -> None:
    bench = Bench(**{"4_14": 40.0})
    bench.send(START, REF_100)
    bench.wait(5.0)
    status, _ = bench.send(START, REF_100)
    assert bench.hz == pytest.approx(40.0)
    assert not status & S.FREQUENCY_OK


@pytest.mark.parametrize(
    ("function", "expected_hz", "running"),
    [(0, 50.0, True), (1, None, True), (2, 0.0, False), (3, 10.0, True), (4, 65.0, True),
     (7, 50.0, True)],
)  # fmt: skip
def test_control_word_timeout_does_what_8_04_says(
    function: int, expected_hz: float | None, running: bool
) -> None:
    bench = Bench(**{"8_03": 1.0, "8_04": function, "3_41": 10.0})
    bench.send(START)
    bench.wait(0.5)
    bench.send(IGNORED)  # polls without a valid word do not feed the watchdog
    bench.wait(0.7)
    at_timeout = bench.hz
    bench.wait(30.0)
    status, _ = bench.send(IGNORED)
    if expected_hz is None:  # freeze: holds what it had when the timeout struck
        expected_hz = at_timeout
    assert bench.hz == pytest.approx(expected_hz)
    assert bool(status & S.RUNNING) is running
    assert bool(status & S.WARNING) is (function != 0)
    assert not status & S.TRIP
    status, _ = bench.send(START)  # a valid word ends the timeout
    assert not status & S.WARNING
    assert not bench.drive.control.timed_out


def test_stop_and_trip_ramps_down_then_trips_with_alarm_17() -> None:
    bench = Bench(**{"8_03": 1.0, "8_04": 5, "3_42": 2.0})
    bench.feed(5.0)
    bench.wait(1.5)  # timed out 1.0 s after the last valid word, ramping down since
    status, _ = bench.send(IGNORED)
    assert status & S.WARNING
    assert status & S.RUNNING
    assert not status & S.TRIP
    bench.wait(2.0)
    status, _ = bench.send(IGNORED)
    assert status & S.TRIP
    assert bench.drive.control.alarm_word == 1 << 4
    assert bench.drive.control.alarm_log[0][0] == 17
    bench.send(START)  # the cause is gone once valid words come back
    assert not bench.send(RESET)[0] & S.TRIP


def test_the_timeout_is_armed_only_by_a_valid_control_word() -> None:
    bench = Bench(**{"8_03": 1.0, "8_04": 2})
    bench.send(IGNORED)
    bench.wait(10.0)
    assert not bench.send(IGNORED)[0] & S.WARNING


def test_setting_8_04_off_ends_a_timeout() -> None:
    bench = Bench(**{"8_03": 1.0, "8_04": 1})
    bench.send(START)
    bench.wait(2.0)
    bench.drive.advance(bench.clock.now())
    assert bench.drive.control.timed_out
    bench.drive.write(804, 0, 0, bench.clock.now())
    assert not bench.drive.control.timed_out
