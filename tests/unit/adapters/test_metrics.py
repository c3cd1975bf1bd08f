"""Prometheus exposition rendered from drive snapshots and line statistics."""

from __future__ import annotations

import re

import pytest

from fcmaster.adapters.gateway import LineInfo
from fcmaster.adapters.metrics import CONTENT_TYPE, format_value, render
from fcmaster.bus.stats import DriveStats, LineStats
from fcmaster.hub import Hub
from fcmaster.protocol.codec import Condition
from fcmaster.state import DriveState, Measured

# One sample line of the text format 0.0.4: name, optional labels, value.
_SAMPLE = re.compile(
    r'^[a-zA-Z_:][a-zA-Z0-9_:]*(\{([a-zA-Z_][a-zA-Z0-9_]*="([^"\\\n]|\\[\\"n])*",?)*\})? '
    r"(-?[0-9.e+-]+|[+-]Inf|NaN)$"
)

PUMP = DriveState(
    name="pump-1",
    bus="line1",
    address=1,
    protocol="danfoss-fc",
    control="bus",
    online=True,
    running=True,
    fault=True,
    output_frequency_hz=42.5,
    reference_pct=85.0,
    status_word=0x0F0B,
    values={
        "16-14": Measured(5.25, "A", 525),
        "16-13": Measured(42.5, "Hz", 425),
        "15-40": Measured("FC-302", "", None),
    },
    alarms=(Condition(14, 'Earth "fault"\\ground'),),
    warnings=(Condition(17, "Control word timeout"),),
    updated_at=1_790_000_000.25,
)
FAN = DriveState(name="fan-1", bus="line1", address=2, protocol="danfoss-fc", control="monitor")


def _line() -> LineInfo:
    stats = LineStats(requests=100, replies=97, timeouts=3, checksum_errors=2, noise_bytes=11)
    stats.up_since = 0.0
    stats.busy_s = 5.0
    for latency in (0.004, 0.012, 0.012, 2.0):
        stats.latency.observe(latency)
    stats.turnaround.observe(0.0003)
    stats.drives["pump-1"] = DriveStats(requests=50, replies=49, timeouts=1, last_latency_s=0.012)
    return LineInfo(
        name="line1",
        port="/dev/ttyUSB0",
        protocol="danfoss-fc",
        baudrate=19200,
        up=True,
        drives=("pump-1", "fan-1"),
        stats=stats.to_json(10.0),
    )


@pytest.fixture
def text() -> str:
    return render([PUMP, FAN], [_line()], Hub())


def _samples(text: str) -> dict[str, str]:
    out = {}
    for line in text.splitlines():
        if not line.startswith("#"):
            key, _, value = line.rpartition(" ")
            out[key] = value
    return out


def test_every_line_is_valid_exposition_and_each_family_is_declared_once(text: str) -> None:
    assert text.endswith("\n")
    declared: list[str] = []
    for line in text.splitlines():
        if line.startswith("# TYPE "):
            declared.append(line.split()[2])
        elif not line.startswith("# HELP "):
            assert _SAMPLE.match(line), line
            name = re.split(r"[{ ]", line, maxsplit=1)[0]
            family = re.sub(r"_(bucket|sum|count)$", "", name)
            assert declared[-1] in (name, family), f"{line} outside its family"
    assert len(declared) == len(set(declared))
    assert CONTENT_TYPE.startswith("text/plain; version=0.0.4")


def test_drive_gauges_carry_bus_and_drive_labels(text: str) -> None:
    samples = _samples(text)
    labels = 'bus="line1",drive="pump-1"'
    assert samples[f"fcmaster_drive_online{{{labels}}}"] == "1"
    assert samples[f"fcmaster_drive_running{{{labels}}}"] == "1"
    assert samples[f"fcmaster_drive_fault{{{labels}}}"] == "1"
    assert samples[f"fcmaster_drive_output_frequency_hz{{{labels}}}"] == "42.5"
    assert samples[f"fcmaster_drive_reference_ratio{{{labels}}}"] == "0.85"
    assert samples[f"fcmaster_drive_status_word{{{labels}}}"] == str(0x0F0B)
    assert samples[f"fcmaster_drive_last_reply_timestamp_seconds{{{labels}}}"] == "1790000000.25"
    assert samples['fcmaster_drive_online{bus="line1",drive="fan-1"}'] == "0"
    # unknown values are absent, not zero
    assert 'fcmaster_drive_output_frequency_hz{bus="line1",drive="fan-1"}' not in samples


def test_every_numeric_measured_value_is_one_series_by_param_and_unit(text: str) -> None:
    samples = _samples(text)
    assert samples['fcmaster_drive_value{bus="line1",drive="pump-1",param="16-14",unit="A"}'] == (
        "5.25"
    )
    assert samples['fcmaster_drive_value{bus="line1",drive="pump-1",param="16-13",unit="Hz"}'] == (
        "42.5"
    )
    assert "15-40" not in text  # text values are not numbers


def test_alarms_and_warnings_count_and_name_their_codes_with_escaped_text(text: str) -> None:
    samples = _samples(text)
    assert samples['fcmaster_drive_alarms{bus="line1",drive="pump-1"}'] == "1"
    assert samples['fcmaster_drive_warnings{bus="line1",drive="pump-1"}'] == "1"
    key = (
        'fcmaster_drive_alarm_active{bus="line1",drive="pump-1",code="14",'
        'text="Earth \\"fault\\"\\\\ground"}'
    )
    assert samples[key] == "1"
    assert samples['fcmaster_drive_alarms{bus="line1",drive="fan-1"}'] == "0"


def test_line_counters_end_in_total_and_histograms_are_cumulative(text: str) -> None:
    samples = _samples(text)
    assert samples['fcmaster_bus_requests_total{bus="line1"}'] == "100"
    assert samples['fcmaster_bus_timeouts_total{bus="line1"}'] == "3"
    assert samples['fcmaster_bus_checksum_errors_total{bus="line1"}'] == "2"
    assert samples['fcmaster_bus_noise_bytes_total{bus="line1"}'] == "11"
    assert samples['fcmaster_bus_up{bus="line1"}'] == "1"
    assert samples['fcmaster_bus_utilisation_ratio{bus="line1"}'] == "0.5"
    name = "fcmaster_bus_transaction_latency_seconds"
    assert samples[f'{name}_bucket{{bus="line1",le="0.005"}}'] == "1"
    assert samples[f'{name}_bucket{{bus="line1",le="0.02"}}'] == "3"
    assert samples[f'{name}_bucket{{bus="line1",le="1.0"}}'] == "3"
    assert samples[f'{name}_bucket{{bus="line1",le="+Inf"}}'] == "4"
    assert samples[f'{name}_count{{bus="line1"}}'] == "4"
    assert float(samples[f'{name}_sum{{bus="line1"}}']) == pytest.approx(2.028)
    assert samples['fcmaster_bus_turnaround_seconds_bucket{bus="line1",le="5e-05"}'] == "0"
    assert "# TYPE fcmaster_bus_transaction_latency_seconds histogram" in text
    assert "# TYPE fcmaster_bus_requests_total counter" in text


def test_per_drive_line_counters_and_hub_figures(text: str) -> None:
    samples = _samples(text)
    assert samples['fcmaster_drive_requests_total{bus="line1",drive="pump-1"}'] == "50"
    assert samples['fcmaster_drive_last_latency_seconds{bus="line1",drive="pump-1"}'] == "0.012"
    assert samples["fcmaster_hub_subscriptions"] == "0"


def test_a_line_without_statistics_yet_still_says_whether_it_is_up() -> None:
    line = LineInfo(
        name="l2", port="sim://l2", protocol="enc", baudrate=9600, up=False, drives=(), stats={}
    )
    samples = _samples(render([], [line]))
    assert samples['fcmaster_bus_up{bus="l2"}'] == "0"
    assert not any(key.startswith("fcmaster_bus_requests_total") for key in samples)


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (1.0, "1"),
        (0.5, "0.5"),
        (5e-05, "5e-05"),
        (float("inf"), "+Inf"),
        (float("-inf"), "-Inf"),
        (float("nan"), "NaN"),
        (True, "1"),
        (7, "7"),
    ],
)
def test_values_are_written_the_way_prometheus_reads_them(value: float, text: str) -> None:
    assert format_value(value) == text
