"""A line's USB adapter in ``/api/v1/buses`` (the ``adapter`` object) and in ``/metrics``."""

from __future__ import annotations

from pathlib import Path

from fcmaster.adapters.gateway import LineInfo
from fcmaster.adapters.metrics import render
from fcmaster.adapters.schemas import LineOut
from tests.fake_machine import FTDI_BY_ID, FakeMachine


def line(adapter: dict[str, object] | None) -> LineInfo:
    return LineInfo(
        name="north", port="/dev/serial/by-id/x", protocol="danfoss-fc", baudrate=19200,
        up=True, drives=("pump-1",), stats={}, adapter=adapter,
    )  # fmt: skip


def samples(text: str) -> dict[str, str]:
    pairs = (row.rpartition(" ") for row in text.splitlines() if not row.startswith("#"))
    return {key: value for key, _, value in pairs}


def test_the_adapter_is_shown_with_its_driver_stable_name_and_latency(tmp_path: Path) -> None:
    machine = FakeMachine(tmp_path)
    machine.add("ttyUSB0", "ftdi_sio", latency_ms=16, by_id=FTDI_BY_ID)
    shown = line(machine.adapter("ttyUSB0").to_json())
    body = LineOut.model_validate(shown.to_json()).model_dump()
    assert body["adapter"] == {
        "device": str(machine.dev / "ttyUSB0"),
        "driver": "ftdi_sio",
        "by_id": str(machine.dev / "serial" / "by-id" / FTDI_BY_ID),
        "by_path": None,
        "latency_ms": 16,
    }
    metrics = samples(render([], [shown]))
    by_id = machine.dev / "serial" / "by-id" / FTDI_BY_ID
    info = (
        f'fcmaster_bus_adapter_info{{bus="north",device="{machine.dev / "ttyUSB0"}",'
        f'driver="ftdi_sio",by_id="{by_id}"}}'
    )
    assert metrics[info] == "1"
    assert metrics['fcmaster_bus_adapter_latency_seconds{bus="north"}'] == "0.016"


def test_a_line_without_an_adapter_shows_null_and_no_adapter_metrics() -> None:
    shown = line(None)
    assert shown.to_json()["adapter"] is None
    assert LineOut.model_validate(shown.to_json()).adapter is None
    assert "fcmaster_bus_adapter" not in render([], [shown])


def test_an_adapter_without_a_timer_has_no_latency_metric(tmp_path: Path) -> None:
    machine = FakeMachine(tmp_path)
    machine.add("ttyUSB1", "ch341-uart")
    metrics = render([], [line(machine.adapter("ttyUSB1").to_json())])
    assert 'driver="ch341-uart",by_id=""' in metrics
    assert "fcmaster_bus_adapter_latency_seconds" not in metrics
