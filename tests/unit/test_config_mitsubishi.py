"""Config semantics of `protocol: mitsubishi` lines (DESIGN.md, protocols/mitsubishi.md §1.1)."""

from __future__ import annotations

import pytest

from fcmaster.bus.codecs import codec_for
from fcmaster.config import parse
from fcmaster.errors import ConfigError
from fcmaster.protocol.mitsubishi import MitsubishiCodec


def line(extra: str = "", drives: str = "      - {name: pump, address: 0}") -> str:
    return f"""
buses:
  - name: mitsu
    port: /dev/ttyUSB0
    protocol: mitsubishi
    stopbits: 2
{extra}
    drives:
{drives}
"""


def problems(text: str) -> list[tuple[str, str]]:
    with pytest.raises(ConfigError) as info:
        parse(text, env={})
    return info.value.problems


def test_factory_settings_send_waiting_digit_0_and_cr() -> None:
    (plan,) = parse(line(), env={}).lines
    assert (plan.terminator, plan.wait_time_ms) == ("cr", 0)
    assert plan.response_delay_s == pytest.approx(0.030)  # digit 0 + 30 ms data check
    codec = codec_for(plan)
    assert isinstance(codec, MitsubishiCodec)
    assert codec.poll(0, None, None).request == b"\x05007A008\r"  # 48+48+55+65+48 = 0x108


def test_a_number_is_the_digit_sent_and_null_leaves_it_out() -> None:
    (plan,) = parse(line("    wait_time_ms: 50\n    terminator: crlf"), env={}).lines
    assert codec_for(plan).poll(0, None, None).request == b"\x05007A50D\r\n"  # 0x108 + 5
    assert plan.response_delay_s == pytest.approx(0.080)
    (plan,) = parse(line("    wait_time_ms: null\n    terminator: none"), env={}).lines
    assert codec_for(plan).poll(0, None, None).request == b"\x05007AD8"  # no digit
    assert plan.response_delay_s == pytest.approx(0.180)  # Pr.123 unknown: 150 ms at worst


def test_a_response_delay_given_in_the_file_is_kept() -> None:
    (plan,) = parse(line("    response_delay_ms: 70"), env={}).lines
    assert plan.response_delay_s == pytest.approx(0.070)


@pytest.mark.parametrize(
    ("extra", "path"),
    [
        ("    wait_time_ms: 15", "buses[0].wait_time_ms"),  # 10 ms steps
        ("    wait_time_ms: 160", "buses[0].wait_time_ms"),
        ("    terminator: lf", "buses[0].terminator"),
        ("    address_format: 31", "buses[0].address_format"),
    ],
)
def test_bad_line_settings_are_named_by_key_path(extra: str, path: str) -> None:
    assert [p for p, _ in problems(line(extra))] == [path]


def test_stations_are_0_to_31_and_monitor_items_must_be_pollable() -> None:
    drives = """      - {name: a, address: 32}
      - {name: b, address: 31, monitor: [H6F, Pr.7, HZZ, 16-13]}
      - {name: c, address: 0, monitor: [H70, H74, H7C]}"""
    found = problems(line(drives=drives))
    assert [path for path, _ in found] == [
        "buses[0].drives[0].address",
        "buses[0].drives[1].monitor[1]",  # a parameter needs the page: not one poll
        "buses[0].drives[1].monitor[2]",
        "buses[0].drives[1].monitor[3]",
    ]
    assert "0-31" in found[0][1]


def test_mitsubishi_keys_belong_to_mitsubishi_lines() -> None:
    text = """
buses:
  - name: fc
    port: /dev/ttyUSB0
    terminator: crlf
    wait_time_ms: 20
    drives: [{name: a, address: 1}]
"""
    assert [p for p, _ in problems(text)] == ["buses[0].terminator", "buses[0].wait_time_ms"]
