"""Each variable's quality and source time, from a drive's compact entry."""

from __future__ import annotations

from typing import Any

from hypothesis import given
from hypothesis import strategies as st

from fcmaster.opcua.quality import STATUS, Quality, Reading, quality, readings

READ_AT = 1_790_000_000.25
FREQUENCY_AT = 1_790_000_000.0


def entry(**changes: Any) -> dict[str, Any]:
    base: dict[str, Any] = {
        "name": "pump-1", "online": True, "at": READ_AT, "running": True, "fault": False,
        "warning": False, "at_reference": True, "direction": "forward", "status_word": 0x0F07,
        "ref": 80.0, "alarms": [], "warnings": ["Live zero error"], "wd": "ok", "f": 40.0,
        "f_at": FREQUENCY_AT, "values": {"Motor Current": [3.5, READ_AT - 2]},
    }  # fmt: skip
    return base | changes


def shown(entry: dict[str, Any], *, line_up: bool = True) -> dict[str, Reading]:
    return {r.path: r for r in readings(entry, line_up=line_up)}


def test_a_live_drive_is_good_with_each_values_own_reading_time() -> None:
    found = shown(entry())
    assert found["Running"] == Reading("Running", True, Quality.GOOD, READ_AT)
    assert found["OutputFrequency"] == Reading("OutputFrequency", 40.0, Quality.GOOD, FREQUENCY_AT)
    motor = Reading("Values/Motor Current", 3.5, Quality.GOOD, READ_AT - 2)
    assert found["Values/Motor Current"] == motor
    assert found["Warnings"].value == ["Live zero error"]
    assert found["Online"] == Reading("Online", True, Quality.GOOD, None)
    assert set(found) == {"Online", "OutputFrequency", "Values/Motor Current", *STATUS}


def test_never_read_is_waiting_for_initial_data_with_no_value() -> None:
    never = entry(online=False, at=None, f=None, f_at=None, running=False, values={}, wd=None)
    for reading in readings(never, line_up=True):
        if reading.path != "Online":
            assert reading.quality is Quality.WAITING, reading
            assert reading.value is None
    assert shown(never)["Online"].value is False


def test_a_silent_drive_or_a_line_down_keeps_the_last_value_uncertain() -> None:
    for found in (shown(entry(online=False)), shown(entry(), line_up=False)):
        assert found["Running"] == Reading("Running", True, Quality.NO_COMMUNICATION, READ_AT)
        assert found["OutputFrequency"].value == 40.0
        assert found["OutputFrequency"].source_at == FREQUENCY_AT
        assert found["Online"].value is False


def test_a_value_the_drive_has_not_given_yet_waits_though_the_drive_answers() -> None:
    assert shown(entry(f=None, f_at=None))["OutputFrequency"].quality is Quality.WAITING
    assert shown(entry(ref=None))["ReferencePercent"].value is None


@given(
    value=st.none() | st.booleans() | st.floats(allow_nan=False),
    read_at=st.none() | st.floats(min_value=0, max_value=4e9),
    answering=st.booleans(),
)
def test_a_bad_quality_never_carries_a_value(
    value: Any, read_at: float | None, answering: bool
) -> None:
    kind = quality(value, read_at, answering=answering)
    assert (kind is Quality.WAITING) == (value is None or read_at is None)
    if kind is not Quality.WAITING:
        assert (kind is Quality.GOOD) == answering
