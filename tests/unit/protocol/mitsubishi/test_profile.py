"""Status bits, run-command data and frequency scaling (protocols/mitsubishi.md §10)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.errors import UsageError
from fcmaster.protocol.drive import ControlIntent, Motion
from fcmaster.protocol.mitsubishi import (
    RunCommand,
    StatusBits,
    decode_status,
    frequency_hz,
    frequency_raw,
    run_command,
)


def test_bit_positions_follow_the_manual_tables() -> None:
    # §10.1 and §10.2, by hand.
    assert (StatusBits.RUN, StatusBits.FORWARD, StatusBits.REVERSE) == (0x01, 0x02, 0x04)
    assert (StatusBits.SU, StatusBits.OL, StatusBits.ABC1, StatusBits.FAULT) == (
        0x08,
        0x10,
        0x80,
        0x8000,
    )
    assert (RunCommand.STF, RunCommand.STR, RunCommand.MRS) == (0x02, 0x04, 0x80)


@pytest.mark.parametrize(
    ("intent", "data"),
    [
        (ControlIntent(Motion.RUN), 0x02),  # §10.2: 02 forward
        (ControlIntent(Motion.RUN, reverse=True), 0x04),  # 04 reverse
        (ControlIntent(Motion.STOP, reverse=True), 0x00),  # 00 stop
        (ControlIntent(Motion.QUICK_STOP), 0x00),
        (ControlIntent(Motion.COAST, reverse=True), 0x80),  # MRS, STF and STR off
    ],
)
def test_run_command_data(intent: ControlIntent, data: int) -> None:
    assert run_command(intent) == data


def test_jog_has_no_run_command_bit() -> None:
    with pytest.raises(UsageError):
        run_command(ControlIntent(Motion.JOG))


def test_extended_status_takes_the_fault_from_bit_15() -> None:
    assert decode_status(0x8000, extended=True).fault
    assert not decode_status(0x0080, extended=True).fault  # ABC1 may be reassigned there
    assert decode_status(0x0080).fault  # H7A has only ABC1


def test_running_comes_from_the_direction_bits_only() -> None:
    # Bit 0 (RUN) is assignable (Pr.190); bits 1 and 2 are fixed.
    assert not decode_status(0x01).running
    assert decode_status(0x02).running
    assert decode_status(0x10).warning  # OL: stall prevention


@given(st.integers(0, 0xFFFF))
def test_frequency_round_trips(raw: int) -> None:
    assert frequency_raw(frequency_hz(raw)) == raw


@pytest.mark.parametrize("hz", [-0.01, 655.36, float("inf"), float("nan")])
def test_frequency_outside_four_digits_is_refused(hz: float) -> None:
    with pytest.raises(UsageError):
        frequency_raw(hz)
