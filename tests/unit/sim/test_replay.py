"""Replaying a capture: which answer each request gets, when, and a BusMaster's view of it."""

from __future__ import annotations

from dataclasses import replace

import pytest

from fcmaster.bus.codecs import codec_for
from fcmaster.bus.frame_log import TX
from fcmaster.bus.master import BusMaster
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.errors import UsageError
from fcmaster.protocol import pcapng
from fcmaster.protocol.framing import Frame
from fcmaster.protocol.modbus_rtu.profiles import BUILT_IN
from fcmaster.protocol.pcapng import Capture, Interface, LineFormat, Packet
from fcmaster.protocol.registry import spec_for
from fcmaster.sim import SimTransport
from fcmaster.sim.danfoss_fc.replay import RULES as FC_RULES
from fcmaster.sim.replay import KnownRequestFramer, ReplayDrive, replay_lines, replay_sim_line
from fcmaster.sim.service import sim_line
from fcmaster.state import FleetState
from tests.fakes import VirtualClock

IFACE = Interface(link_type=147, name="north", description="danfoss-fc 9600 8N1", speed=9600)
CHAR_US = 10 / 9600 * 1e6  # 8N1: ten bits a character


def out(at_us: float, data: bytes) -> Packet:
    return Packet(0, round(at_us), data, pcapng.OUTBOUND)


def into(at_us: float, data: bytes) -> Packet:
    return Packet(0, round(at_us), data, pcapng.INBOUND)


def test_each_request_gets_what_followed_it_each_time_with_its_turnaround() -> None:
    a, b = b"AAAA", b"BB"
    wire_a = 8 * CHAR_US  # four bytes out, four back
    packets = [
        out(0, a),
        into(wire_a + 20_000, b"r1r1"),  # 20 ms beyond the wire time
        out(100_000, a),  # no reply: a timeout in the field
        out(200_000, a),
        into(200_000 + wire_a + 5_000, b"r3r3"),
        out(300_000, b),
        into(300_000 + 1_000, b"~"),  # noise, then the reply: served together
        into(300_000 + 5 * CHAR_US + 7_000, b"rb"),
    ]
    (line,) = replay_lines(Capture("", [IFACE], packets))
    assert line.name == "north"
    assert line.format == LineFormat("danfoss-fc", 9600, 8, "N", 1)
    (r1, d1), (none, _), (r3, d3) = line.answers[a]
    assert (r1, none, r3) == (b"r1r1", None, b"r3r3")
    assert d1 == pytest.approx(0.020, abs=1e-5)
    assert d3 == pytest.approx(0.005, abs=1e-5)
    ((rb, db),) = line.answers[b]
    assert rb == b"~rb"
    assert db == pytest.approx(0.007, abs=1e-5)


def test_a_replayed_drive_serves_in_order_and_stays_silent_for_unknown_requests() -> None:
    served: list[tuple[bytes, bytes | None]] = []
    drive = ReplayDrive(
        {b"A": [(b"1", 0.01), (None, 0.0), (b"3", 0.02)]},
        lambda request, reply: served.append((request, reply)),
    )
    replies = [drive.handle(b"A", 0.0) for _ in range(5)]
    assert replies == [b"1", None, b"3", b"3", b"3"]
    assert drive.response_delay_s == 0.02
    assert drive.handle(b"Z", 0.0) is None
    assert served[-1] == (b"Z", None)
    assert served[0] == (b"A", b"1")


def test_the_framer_cuts_known_requests_and_reports_unknown_bytes_as_one_piece() -> None:
    unknown: list[bytes] = []
    framer = KnownRequestFramer([b"\x02AB", b"\x02CD"], unknown.append)
    pieces = []
    for byte in b"xy\x02AB\x02ZZ\x02CD":
        framer.feed(bytes([byte]))
        while (piece := framer.next_frame()) is not None:
            pieces.append(piece)
    frames = [p.data for p in pieces if isinstance(p, Frame)]
    assert frames == [b"\x02AB", b"\x02CD"]
    assert unknown == [b"xy", b"\x02ZZ"]
    assert sum(len(p.data) for p in pieces) == len(b"xy\x02AB\x02ZZ\x02CD")
    framer.feed(b"\x02Q")
    assert framer.next_frame() is not None  # "\x02Q" is no known prefix: skipped
    framer.feed(b"\x02A")  # an unfinished known request, then a pause
    assert framer.next_frame() is None
    framer.reset()
    assert unknown[-1] == b"\x02Q\x02A"
    assert framer.next_frame() is not None
    assert framer.next_frame() is None


def test_a_capture_of_another_program_is_refused_by_name() -> None:
    stranger = Interface(link_type=1, name="eth0", description="")
    with pytest.raises(UsageError, match="eth0"):
        replay_lines(Capture("", [stranger], []))
    with pytest.raises(UsageError, match="no lines"):
        replay_lines(Capture("", [], []))


def _capture_of(master: BusMaster) -> Capture:
    plan = master.plan
    fmt = LineFormat(plan.protocol, plan.baudrate, plan.databits, plan.parity, plan.stopbits)
    iface = Interface(pcapng.LINK_TYPES[plan.protocol], plan.name, str(fmt), plan.baudrate)
    packets = [
        Packet(0, round(mono * 1e6), data, pcapng.OUTBOUND if d == TX else pcapng.INBOUND)
        for _, d, mono, _, data in master.frames.since(0).frames
    ]
    return pcapng.decode(pcapng.encode(Capture("test", [iface], packets)))


def _plan(protocol: str) -> LinePlan:
    # modbus-rtu drives each follow a profile: the built-ins' first two here
    profiled = spec_for(protocol).new_profiled_codec is not None
    return LinePlan(
        name="north",
        port="sim://north",
        protocol=protocol,
        drives=tuple(
            DrivePlan(
                name=f"d{a}", address=a, profile=tuple(BUILT_IN.values())[a] if profiled else None
            )
            for a in (1, 2)
        ),
    )


@pytest.mark.parametrize("protocol", sorted(pcapng.LINK_TYPES))
async def test_a_master_on_the_replay_gets_the_replies_the_captured_master_got(
    protocol: str,
) -> None:
    plan = _plan(protocol)
    clock = VirtualClock()
    line = sim_line(plan, {}, clock=clock)
    first = BusMaster(plan, codec=codec_for(plan), transport=SimTransport(line, clock), clock=clock)
    async with first:
        await clock.run_for(2.0)
    capture = _capture_of(first)
    (replayed,) = replay_lines(capture)

    clock = VirtualClock()
    replay = replay_sim_line(replayed, clock=clock)
    transport = SimTransport(replay, clock)
    second = BusMaster(plan, codec=codec_for(plan), transport=transport, clock=clock)
    async with second:
        await clock.run_for(2.0)
    before = [(d, data) for _, d, _, _, data in first.frames.since(0).frames]
    after = [(d, data) for _, d, _, _, data in second.frames.since(0).frames]
    assert len(before) > 50
    assert after[:50] == before[:50]  # the same requests, answered with the same bytes
    assert second.stats.replies >= 0.9 * first.stats.replies
    assert second.stats.timeouts == first.stats.timeouts == 0


def _mid_run_capture(master: BusMaster, after_s: float) -> Capture:
    """The master's frames from ``after_s`` on: a capture begun on a line already running."""
    whole = _capture_of(master)
    start = whole.packets[0].timestamp_us + round(after_s * 1e6)
    later = [p for p in whole.packets if p.timestamp_us >= start]
    while later and later[0].direction == pcapng.INBOUND:
        later.pop(0)  # a reply whose request came before the capture began
    return replace(whole, packets=later)


async def _capture_of_bus_drives(protocol: str = "danfoss-fc") -> tuple[LinePlan, Capture]:
    """A capture begun mid-run on a master commanding two drives, the first one running."""
    base = _plan(protocol)
    first_address = codec_for(base).addresses.start + 1
    addresses = (first_address, first_address + 1)
    plan = replace(
        base,
        drives=tuple(
            DrivePlan(name=f"d{i}", address=a, control=True, profile=drive.profile)
            for i, (a, drive) in enumerate(zip(addresses, base.drives, strict=True), 1)
        ),
    )
    clock = VirtualClock()
    line = sim_line(plan, {"drives": {first_address: {"running_hz": 30}}}, clock=clock)
    first = BusMaster(plan, codec=codec_for(plan), transport=SimTransport(line, clock), clock=clock)
    async with first:
        await clock.run_for(3.0)
    return plan, _mid_run_capture(first, 1.5)


async def _states_on_replay(plan: LinePlan, capture: Capture) -> FleetState:
    (replayed,) = replay_lines(capture)
    clock = VirtualClock()
    replay = replay_sim_line(replayed, clock=clock)
    fleet = FleetState((plan,), emit=lambda event: None, clock=clock)
    master = BusMaster(
        plan, codec=codec_for(plan), transport=SimTransport(replay, clock), clock=clock,
        observer=fleet,
    )  # fmt: skip
    async with master:
        await clock.run_for(2.0)
    return fleet


@pytest.mark.parametrize("control", [True, False])
@pytest.mark.parametrize("protocol", sorted(pcapng.LINK_TYPES))
async def test_a_daemon_on_the_replay_sees_the_captured_drives_whatever_it_commands(
    protocol: str, control: bool
) -> None:
    # Captured mid-run from a master commanding its drives: a master starting afresh (FC:
    # first polls with the control word marked not valid) or a monitor-only one asks the
    # same questions with other control words, and gets the captured drives' answers.
    plan, capture = await _capture_of_bus_drives(protocol)
    drives = tuple(replace(d, control=control) for d in plan.drives)
    fleet = await _states_on_replay(replace(plan, drives=drives), capture)
    one, two = fleet.get("north", "d1"), fleet.get("north", "d2")
    assert one is not None
    assert two is not None
    assert one.online
    assert two.online
    assert one.running
    assert not two.running
    assert one.output_frequency_hz == pytest.approx(30.0, abs=0.5)


async def test_a_commissioning_poll_gets_the_drives_latest_status_and_unknowns_stay_silent() -> (
    None
):
    plan, capture = await _capture_of_bus_drives()
    (replayed,) = replay_lines(capture)
    drive = ReplayDrive(replayed.answers, rules=FC_RULES, sequence=replayed.sequence)
    codec = codec_for(plan)
    one, two = (drive.address for drive in plan.drives)
    for address, running in ((one, True), (two, False)):
        poll = codec.poll(address, None, None)  # a scan's: control word 0, no parameter
        assert poll.request not in replayed.answers
        reply = drive.handle(poll.request, 0.0)
        assert reply is not None
        status = codec.parse(poll, reply).status
        assert status is not None
        assert status.running is running
        read = codec.read(address, codec.parameter("16-14"), 0, None)[0]  # polled: answered
        value = codec.parse(read, drive.handle(read.request, 0.0) or b"").value
        assert value is not None
        assert value.unit == "A"
    never_read = codec.read(one, codec.parameter("1-20"), 0, None)[0]
    assert drive.handle(never_read.request, 0.0) is None  # a question never asked
    assert drive.handle(codec.poll(9, None, None).request, 0.0) is None  # a drive not there
