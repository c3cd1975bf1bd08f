"""A drive as Sparkplug device metrics (DESIGN.md "Sparkplug B"), and what changed between two.

Each metric keeps its datatype from birth to death: a host refuses a DDATA whose metric it
was not told of in the DBIRTH, or whose type differs. A value a drive has not reported yet is
a null of the metric's type. Engineering units travel as the ``engUnit`` property, which
Ignition's MQTT Engine and Tahu's hosts read. Timestamps are the time each value was read
from the drive (milliseconds since the epoch), so history and live data sort as they happened.
"""

from __future__ import annotations

from dataclasses import dataclass

from fcmaster.adapters.sparkplug.payload import (
    DataType,
    Metric,
    PropertySet,
    PropertyValue,
    Value,
)
from fcmaster.drive_state import DriveState

__all__ = [
    "CONTROL_METRICS",
    "LAST_OUTCOME",
    "LAST_REASON",
    "REFERENCE_HZ",
    "RESET",
    "RUN",
    "Reading",
    "birth_metrics",
    "changed",
    "data_metrics",
    "device_readings",
]

RUN = "Control/Run"
REFERENCE_HZ = "Control/Reference Hz"
RESET = "Control/Reset"
LAST_OUTCOME = "Control/Last Outcome"
LAST_REASON = "Control/Last Reason"
CONTROL_METRICS = (RUN, REFERENCE_HZ, RESET)  # the writable ones (DCMD)


@dataclass(slots=True, frozen=True)
class Reading:
    """One metric's current value: its type, value (None: not known), unit and time (ms)."""

    datatype: DataType
    value: Value | None
    unit: str = ""
    at_ms: int | None = None


def _ms(wall: float | None) -> int | None:
    return None if wall is None else round(wall * 1000)


def _conditions(state: DriveState, kind: str) -> str:
    found = state.alarms if kind == "alarm" else state.warnings
    return "; ".join(f"{c.text} ({c.code})" for c in found)


def device_readings(
    state: DriveState,
    nominal_hz: float,
    *,
    outcome: tuple[str, str] = ("", ""),
) -> dict[str, Reading]:
    """Every metric of ``state`` by name; ``outcome`` is the last DCMD's outcome and reason."""
    at = _ms(state.updated_at)
    frequency_at = _ms(state.output_frequency_updated_at) or at
    double, boolean, text = DataType.DOUBLE, DataType.BOOLEAN, DataType.STRING
    reference_hz = None if state.reference_pct is None else state.reference_pct * nominal_hz / 100.0
    readings = {
        "Output Frequency": Reading(double, state.output_frequency_hz, "Hz", frequency_at),
        "Reference": Reading(double, state.reference_pct, "%", at),
        "Status/Running": Reading(boolean, state.running, at_ms=at),
        "Status/Fault": Reading(boolean, state.fault, at_ms=at),
        "Status/Warning": Reading(boolean, state.warning, at_ms=at),
        "Status/At Reference": Reading(boolean, state.at_reference, at_ms=at),
        "Status/Word": Reading(DataType.INT64, state.status_word, at_ms=at),
        "Status/Direction": Reading(text, state.direction, at_ms=at),
        "Alarms": Reading(text, _conditions(state, "alarm"), at_ms=at),
        "Warnings": Reading(text, _conditions(state, "warning"), at_ms=at),
        "Watchdog/Verdict": Reading(
            text, None if state.watchdog is None else state.watchdog.verdict.value, at_ms=at
        ),
    }
    for key, measured in state.values.items():
        value = measured.value
        datatype = text if isinstance(value, str) else double
        name = f"Values/{measured.name or key}"
        readings[name] = Reading(
            datatype,
            float(value) if datatype == double else value,
            measured.unit,
            _ms(measured.updated_at) or at,
        )
    readings[RUN] = Reading(boolean, state.running, at_ms=at)
    readings[REFERENCE_HZ] = Reading(double, reference_hz, "Hz", at)
    readings[RESET] = Reading(boolean, False, at_ms=at)
    readings[LAST_OUTCOME] = Reading(text, outcome[0], at_ms=at)
    readings[LAST_REASON] = Reading(text, outcome[1], at_ms=at)
    return readings


def changed(before: dict[str, Reading], after: dict[str, Reading]) -> dict[str, Reading]:
    """The readings of ``after`` whose value differs from ``before`` (or are new)."""
    return {
        name: reading
        for name, reading in after.items()
        if (old := before.get(name)) is None
        or old.value != reading.value
        or old.datatype != reading.datatype
    }


def _metric(name: str, reading: Reading, *, historical: bool, units: bool) -> Metric:
    properties = None
    if units and reading.unit:
        properties = PropertySet((("engUnit", PropertyValue(DataType.STRING, reading.unit)),))
    return Metric(
        name=name,
        timestamp=reading.at_ms,
        datatype=reading.datatype,
        is_historical=historical,
        is_null=reading.value is None,
        properties=properties,
        value=reading.value,
    )


def birth_metrics(readings: dict[str, Reading]) -> tuple[Metric, ...]:
    """A DBIRTH's metrics: every reading, with its engineering unit."""
    return tuple(_metric(n, r, historical=False, units=True) for n, r in readings.items())


def data_metrics(readings: dict[str, Reading], *, historical: bool = False) -> tuple[Metric, ...]:
    """A DDATA's metrics (units were told at birth)."""
    return tuple(_metric(n, r, historical=historical, units=False) for n, r in readings.items())
