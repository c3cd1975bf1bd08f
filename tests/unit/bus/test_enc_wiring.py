"""ENC lines from config to codec: per-line encodings, addresses, monitors, nominal frequency."""

from __future__ import annotations

import dataclasses

import pytest

from fcmaster.bus.codecs import codec_for
from fcmaster.bus.commands import Action, Command, Outcome
from fcmaster.bus.plan import DrivePlan, LinePlan, OnStart
from fcmaster.bus.planner import Planner, StepKind
from fcmaster.config import parse
from fcmaster.errors import ConfigError
from fcmaster.protocol.codec import DriveStatus, Reply
from fcmaster.protocol.drive import ControlIntent, Motion
from fcmaster.protocol.enc import EncCodec, NumberEncoding, decode_request

BUS = """
buses:
  - name: line1
    port: /dev/ttyUSB0
    protocol: {protocol}
    {extra}
    drives:
      - {{name: a, address: {address}, monitor: [{monitor}]}}
"""


def config(
    *, protocol: str = "enc", extra: str = "", address: int = 1, monitor: str = "F0.01"
) -> LinePlan:
    text = BUS.format(protocol=protocol, extra=extra, address=address, monitor=monitor)
    return parse(text).lines[0]


def problems(**kwargs: object) -> list[tuple[str, str]]:
    with pytest.raises(ConfigError) as caught:
        config(**kwargs)  # type: ignore[arg-type]  # keyword values of mixed types
    return caught.value.problems


def test_an_enc_line_gets_the_enc_codec_with_hex_by_default() -> None:
    codec = codec_for(config())
    assert isinstance(codec, EncCodec)
    assert codec.address_encoding is NumberEncoding.HEX
    assert codec.response_encoding is NumberEncoding.HEX
    assert codec.fault_encoding is NumberEncoding.HEX
    assert codec.addresses == range(1, 127)


def test_the_encodings_are_per_line_options() -> None:
    keys = ("address_encoding", "response_encoding", "fault_encoding")
    plan = config(extra="\n    ".join(f"{key}: decimal" for key in keys), address=12)
    codec = codec_for(plan)
    assert isinstance(codec, EncCodec)
    assert codec.addresses == range(1, 100)
    assert codec.poll(12, None, None).request.startswith(b"~12")  # the digits as printed
    assert codec.response_encoding is NumberEncoding.DECIMAL
    assert codec.fault_encoding is NumberEncoding.DECIMAL


@pytest.mark.parametrize("key", ["address_encoding", "response_encoding", "fault_encoding"])
def test_enc_keys_on_another_protocols_line_are_errors(key: str) -> None:
    assert problems(protocol="danfoss-fc", extra=f"{key}: hex", monitor="16-13") == [
        (f"buses[0].{key}", "only enc lines have one")
    ]


def test_an_unknown_encoding_is_named() -> None:
    found = problems(extra="fault_encoding: bcd")
    assert found[0][0] == "buses[0].fault_encoding"
    assert "'bcd'" in found[0][1]


@pytest.mark.parametrize("address", [0, 127])
def test_broadcast_addresses_cannot_name_a_drive(address: int) -> None:
    ((path, reason),) = problems(address=address)
    assert path == "buses[0].drives[0].address"
    assert "1-126" in reason
    assert "broadcast" in reason


def test_decimal_addresses_stop_at_99() -> None:
    ((path, reason),) = problems(extra="address_encoding: decimal", address=100)
    assert path == "buses[0].drives[0].address"
    assert "1-99" in reason


def test_monitor_names_are_checked_by_the_enc_codec() -> None:
    ((path, reason),) = problems(monitor="16-13")
    assert path == "buses[0].drives[0].monitor[0]"
    assert "F0.01" in reason
    assert config(monitor="running_frequency, 11/0003, F2.16").drives[0].monitor == (
        "running_frequency",
        "11/0003",
        "F2.16",
    )


def line(*nominals: float) -> LinePlan:
    drives = tuple(
        DrivePlan(name=f"d{i}", address=i, control=True, nominal_frequency_hz=hz,
                  max_frequency_hz=hz)
        for i, hz in enumerate(nominals, 1)
    )  # fmt: skip
    return LinePlan(name="l", port="x", protocol="enc", drives=drives)


def test_percent_becomes_hz_by_each_drives_nominal_frequency() -> None:
    codec = codec_for(line(50.0, 60.0))
    run = ControlIntent(Motion.RUN, reference_pct=50.0)
    assert decode_request(codec.control(1, run)[0].request).data == 2500  # 25.00 Hz
    assert decode_request(codec.control(2, run)[0].request).data == 3000  # 30.00 Hz


def test_a_broadcast_reference_needs_one_nominal_frequency() -> None:
    run = ControlIntent(Motion.RUN, reference_pct=50.0)
    assert decode_request(codec_for(line(60.0, 60.0)).control(0, run)[0].request).data == 3000
    planner = Planner(line(50.0, 60.0), codec_for(line(50.0, 60.0)))
    (completion,) = planner.submit(None, Command(action=Action.START, reference_pct=50.0), 1)
    assert completion.result.outcome is Outcome.INVALID
    assert "nominal frequency" in completion.result.reason


def test_quick_stop_goes_first_as_the_emergency_stop() -> None:
    plan = line(50.0)
    planner = Planner(plan, codec_for(plan))
    planner.submit("d1", Command(action=Action.READ, parameter="F0.01"), 1)
    planner.submit("d1", Command(action=Action.QUICK_STOP), 2)
    step = planner.next_step(0.0)
    assert step is not None
    assert step.kind is StepKind.COMMAND
    assert step.exchange.request == b"~010C000D01A8\r"  # 12/000D, the manual's example


def test_on_start_stop_sends_the_stop_on_its_own_before_any_poll() -> None:
    plan = dataclasses.replace(
        line(50.0),
        drives=(dataclasses.replace(line(50.0).drives[0], on_start=OnStart.STOP),),
    )
    planner = Planner(plan, codec_for(plan))
    step = planner.next_step(0.0)
    assert step is not None
    assert step.kind is StepKind.COMMAND
    assert step.exchange.request == b"~010C0007019B\r"  # 12/0007 stop, the manual's example
    report = planner.on_reply(step, Reply(address=1), 0.01)
    assert report.completions == []  # acknowledged; done once a status shows it stopped
    after = planner.next_step(0.02)
    assert after is not None
    assert after.kind is StepKind.POLL
    stopped = DriveStatus(word=0, running=False, fault=False, warning=False, at_reference=False)
    report = planner.on_reply(after, Reply(address=1, status=stopped), 0.03)
    assert [c.result.outcome for c in report.completions] == [Outcome.DONE]
