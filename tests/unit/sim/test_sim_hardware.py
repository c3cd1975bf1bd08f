"""The simulator as hardware behaves, in virtual time: a USB adapter's latency timer and
its chunks, a master at the wrong baud rate, and two drives answering on one address."""

from __future__ import annotations

import pytest

from fcmaster.config import parse
from fcmaster.errors import ConfigError, UsageError
from fcmaster.protocol.danfoss_fc import encode_telegram
from fcmaster.sim import DriveSettings, LineSettings, build_line
from fcmaster.sim.adapter import LatencyAdapter
from fcmaster.sim.service import sim_settings
from tests.fakes import FakeClock
from tests.unit.sim.wire import frames_in, read

CHAR_S = 11 / 19200
FC_EXCHANGE_S = 32 * CHAR_S + 0.010  # request and reply, 16 characters each, and 8-35


def test_a_reply_waits_for_the_adapters_next_tick() -> None:
    clock = FakeClock()
    started = clock.now()
    line = build_line(
        LineSettings(baudrate=19200, adapter_latency_ms=16), [(1, DriveSettings())], clock=clock
    )
    line.write(encode_telegram(read(1, 1613)))
    on_the_wire = line.next_delivery()  # 28.3 ms: past the first tick at 16 ms
    assert on_the_wire is not None
    assert on_the_wire == pytest.approx(started + FC_EXCHANGE_S)
    clock.time = on_the_wire
    assert line.receive() == b""  # arrived at the adapter, held there
    tick = started + 0.032
    assert line.next_delivery() == pytest.approx(tick)
    clock.time = tick - 1e-6
    assert line.receive() == b""
    clock.time = tick
    reply = line.receive()
    assert len(frames_in(reply)) == 1
    assert line.next_delivery() is None


def test_without_an_adapter_the_reply_comes_when_it_ends() -> None:
    clock = FakeClock()
    line = build_line(LineSettings(baudrate=19200), [(1, DriveSettings())], clock=clock)
    line.write(encode_telegram(read(1, 1613)))
    assert line.next_delivery() == pytest.approx(clock.now() + FC_EXCHANGE_S)


def test_a_reply_that_spans_a_tick_arrives_in_two_chunks() -> None:
    clock = FakeClock()
    started = clock.now()
    # 1 ms ticks: the 16-character reply (9.2 ms on the wire) spans nine of them.
    line = build_line(
        LineSettings(baudrate=19200, adapter_latency_ms=1), [(1, DriveSettings())], clock=clock
    )
    line.write(encode_telegram(read(1, 1613)))
    reply_end = line.next_delivery()
    assert reply_end is not None
    assert reply_end == pytest.approx(started + FC_EXCHANGE_S)  # 28.3 ms
    clock.time = reply_end
    first = line.receive()  # what arrived by the last tick (28 ms) goes at once
    reply_start = reply_end - 16 * CHAR_S
    assert len(first) == int((started + 0.028 - reply_start) / CHAR_S)  # 15 of 16
    assert line.next_delivery() == pytest.approx(started + 0.029)
    clock.time = started + 0.029
    rest = line.receive()
    assert len(first) + len(rest) == 16
    assert len(frames_in(first + rest)) == 1


def test_a_full_packet_goes_before_the_tick() -> None:
    adapter = LatencyAdapter(0.016, epoch=0.0, packet=4)
    adapter.hold(bytes(range(10)), end=0.010, char_s=0.001)  # bytes 0-9 arrive 1 ms apart
    assert adapter.next_release() == pytest.approx(0.004)  # the fourth byte fills a packet
    assert adapter.release(0.004) == bytes([0, 1, 2, 3])
    assert adapter.release(0.010) == bytes([4, 5, 6, 7])  # full again at 0.008
    assert adapter.next_release() == pytest.approx(0.016)  # two left: the tick
    assert adapter.release(0.016) == bytes([8, 9])
    assert adapter.chunks == 3


@pytest.mark.parametrize("latency_ms", [0, -1, 256])
def test_a_latency_outside_1_to_255_ms_is_refused(latency_ms: float) -> None:
    with pytest.raises(UsageError, match="1-255 ms"):
        LineSettings(adapter_latency_ms=latency_ms)


def test_a_master_at_another_baud_rate_is_not_understood() -> None:
    clock = FakeClock()
    line = build_line(LineSettings(baudrate=19200), [(1, DriveSettings())], clock=clock)
    line.hear_master_at(9600)
    line.write(encode_telegram(read(1, 1613)))
    assert line.next_delivery() is None  # no drive heard a request
    assert line.counters.requests == 0
    assert line.counters.misframed_bytes == 16
    line.hear_master_at(19200)  # put right: understood again
    clock.time += 1.0
    line.write(encode_telegram(read(1, 1613)))
    assert line.counters.requests == 1
    assert line.next_delivery() is not None


@pytest.mark.parametrize("parity", ["N", "O"])
def test_a_master_with_another_parity_is_not_understood(parity: str) -> None:
    clock = FakeClock()
    line = build_line(LineSettings(baudrate=19200, parity="E"), [(1, DriveSettings())], clock=clock)
    line.hear_master_at(19200, parity)
    line.write(encode_telegram(read(1, 1613)))
    assert line.next_delivery() is None
    assert line.counters.misframed_bytes == 16
    line.hear_master_at(19200, "E")
    clock.time += 1.0
    line.write(encode_telegram(read(1, 1613)))
    assert line.counters.requests == 1


def test_two_drives_on_one_address_garble_each_others_reply() -> None:
    clock = FakeClock()
    line = build_line(
        LineSettings(baudrate=19200, duplicate_addresses=True),
        [(1, DriveSettings()), (1, DriveSettings(response_delay_s=0.011))],
        clock=clock,
    )
    line.write(encode_telegram(read(1, 1613)))
    assert line.counters.replies == 2
    assert line.counters.collisions == 1
    assert line.transactions[-1].faults == ["collision"]
    clock.time += 0.1
    assert frames_in(line.receive()) == []  # no reply survives


def test_repeated_addresses_are_still_refused_unless_asked_for() -> None:
    with pytest.raises(UsageError, match="more than once"):
        build_line(LineSettings(), [(1, DriveSettings()), (1, DriveSettings())], clock=FakeClock())


def test_a_config_gives_a_simulated_line_its_adapter() -> None:
    plan = parse("buses: [{name: a, port: sim://a, drives: [{name: d, address: 1}]}]").lines[0]
    line, _ = sim_settings(plan, {"adapter_latency_ms": 16})
    assert line.adapter_latency_ms == 16
    with pytest.raises(ConfigError) as bad:
        sim_settings(plan, {"adapter_latency_ms": 0})
    assert bad.value.problems[0][0] == "buses.a.simulation.adapter_latency_ms"
