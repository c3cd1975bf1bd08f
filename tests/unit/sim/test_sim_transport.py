"""SimTransport: the in-process Transport, in virtual time; and sim:// lookup."""

from __future__ import annotations

import pytest

import fcmaster.sim
from fcmaster.errors import PortError, ReplyTimeout, UsageError
from fcmaster.protocol.danfoss_fc import decode_telegram, encode_telegram
from fcmaster.sim import (
    DriveSettings,
    LineSettings,
    SimRegistry,
    SimTransport,
    build_line,
    sim_name,
)
from fcmaster.transport.pipe import Transport
from tests.fakes import FakeClock, VirtualClock
from tests.unit.sim.wire import START, control, fc_line, read


async def test_read_returns_the_reply_at_the_time_its_last_byte_arrives() -> None:
    clock = VirtualClock()
    transport: Transport = SimTransport(fc_line(clock, (1,)), clock)
    await transport.open()
    written = clock.now()
    await transport.write(encode_telegram(read(1, 1613)))
    reply = await clock.complete(transport.read(written + 1.0))
    assert clock.now() == pytest.approx(written + 32 * 11 / 19200 + 0.010)
    assert decode_telegram(reply, from_drive=True).pnu == 1613


async def test_read_times_out_at_the_deadline_when_nothing_comes() -> None:
    clock = VirtualClock()
    transport = SimTransport(fc_line(clock, (1,)), clock)
    await transport.open()
    await transport.write(encode_telegram(control(9, START)))  # nobody at 9
    with pytest.raises(ReplyTimeout):
        await clock.complete(transport.read(clock.now() + 0.1))
    assert clock.now() == pytest.approx(1000.1)


async def test_a_reply_later_than_the_deadline_is_left_for_discard_input() -> None:
    clock = VirtualClock()
    line = fc_line(clock, (1,))
    transport = SimTransport(line, clock)
    await transport.open()
    await transport.write(encode_telegram(control(1, START)))
    with pytest.raises(ReplyTimeout):
        # before the reply can have arrived
        await clock.complete(transport.read(clock.now() + 0.005))
    assert transport.discard_input() == b""  # still on its way
    await clock.run_for(0.1)
    assert len(transport.discard_input()) == 8


async def test_a_closed_transport_refuses_to_carry_bytes() -> None:
    clock = FakeClock()
    transport = SimTransport(fc_line(clock, (1,)), clock, port="sim://x")
    with pytest.raises(PortError, match="not open"):
        await transport.write(b"\x02")
    await transport.open()
    await transport.close()
    await transport.close()
    with pytest.raises(PortError):
        await transport.read(clock.now() + 1.0)


async def test_registry_resolves_sim_urls() -> None:
    clock = FakeClock()
    registry = SimRegistry()
    line = build_line(LineSettings(name="line1"), [(1, DriveSettings())], clock=clock)
    registry.add("line1", line)
    transport = registry.transport("sim://line1", clock)
    assert transport.line is line
    assert transport.port == "sim://line1"
    assert registry.names == ("line1",)
    assert sim_name("sim://line1") == "line1"
    assert sim_name("/dev/ttyUSB0") is None
    with pytest.raises(PortError, match="no simulated line"):
        registry.transport("sim://other", clock)
    with pytest.raises(UsageError):
        registry.transport("/dev/ttyUSB0", clock)
    with pytest.raises(UsageError, match="already"):
        registry.add("line1", line)


def test_build_line_refuses_what_it_cannot_simulate() -> None:
    clock = FakeClock()
    with pytest.raises(UsageError, match="modbus"):
        build_line(LineSettings(protocol="modbus"), [], clock=clock)
    with pytest.raises(UsageError, match="0-31"):  # Mitsubishi stations
        build_line(LineSettings(protocol="mitsubishi"), [(32, DriveSettings())], clock=clock)
    with pytest.raises(UsageError, match="1-126"):
        build_line(LineSettings(), [(127, DriveSettings())], clock=clock)
    with pytest.raises(UsageError, match="more than once"):
        build_line(LineSettings(), [(3, DriveSettings()), (3, DriveSettings())], clock=clock)
    with pytest.raises(UsageError, match="parity"):
        LineSettings(parity="X")


def test_exported_names_exist() -> None:
    for name in fcmaster.sim.__all__:
        assert hasattr(fcmaster.sim, name), name
    assert sorted(fcmaster.sim.__all__) == sorted(set(fcmaster.sim.__all__))
