"""Fault plans: the --faults text form, validation, and how line and drive plans combine."""

from __future__ import annotations

import pytest

from fcmaster.errors import UsageError
from fcmaster.sim import FaultPlan, parse_faults


def test_every_key_of_the_text_form_parses() -> None:
    plan = parse_faults(
        "drop=0.05, corrupt=0.01,noise=0.02,noise_bytes=3,late=0.1,late_s=0.3,"
        "silent=0.001,silent_s=4,silent_at=10-15,silent_at=30-31.5,echo,seed=7"
    )
    assert plan == FaultPlan(
        drop=0.05, corrupt=0.01, noise=0.02, noise_bytes=3, late=0.1, late_s=0.3,
        silent=0.001, silent_s=4.0, silent_periods=((10.0, 15.0), (30.0, 31.5)),
        echo=True, seed=7,
    )  # fmt: skip


def test_empty_text_is_a_quiet_plan() -> None:
    assert parse_faults("").is_quiet
    assert parse_faults("seed=3").is_quiet
    assert not parse_faults("echo=1").is_quiet
    assert parse_faults("echo=0") == FaultPlan()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("drop=2", "outside 0…1"),
        ("drop", "needs a value"),
        ("drop=lots", "not a number"),
        ("seed=1.5", "whole number"),
        ("silent_at=5", "START-END"),
        ("silent_at=5-2", "start < end"),
        ("late_s=-1", "≥ 0"),
        ("jitter=0.1", "unknown fault 'jitter'"),
        ("echo=maybe", "echo=1"),
        ("noise_bytes=0", "at least 1"),
    ],
)
def test_bad_fault_text_names_the_problem(text: str, message: str) -> None:
    with pytest.raises(UsageError, match=message):
        parse_faults(text)


def test_silent_periods_are_half_open_windows() -> None:
    plan = FaultPlan(silent_periods=((1.0, 2.0),))
    assert [plan.is_silent_period(t) for t in (0.99, 1.0, 1.99, 2.0)] == [False, True, True, False]


def test_drive_plan_adds_to_line_plan() -> None:
    line = FaultPlan(drop=0.5, late=0.1, late_s=0.2, echo=True, noise=0.3,
                     silent_periods=((1.0, 2.0),))  # fmt: skip
    drive = FaultPlan(drop=0.5, late=0.2, late_s=1.0, silent_periods=((5.0, 6.0),))
    merged = line.merged(drive)
    assert merged.drop == pytest.approx(0.75)
    assert merged.late == pytest.approx(0.28)
    assert merged.late_s == 1.0
    assert merged.echo
    assert merged.noise == 0.3
    assert merged.silent_periods == ((1.0, 2.0), (5.0, 6.0))
    assert line.merged(FaultPlan()) == line
