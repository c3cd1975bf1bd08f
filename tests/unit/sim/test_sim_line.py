"""The simulated line: wire timing, addressing, broadcasts, collisions, gaps and echo."""

from __future__ import annotations

import pytest

from fcmaster.errors import UsageError
from fcmaster.protocol.danfoss_fc import AddressFormat, FcFramer, Telegram, encode_telegram
from fcmaster.sim import DriveSettings, FaultPlan, LineSettings, SimLine, build_line
from tests.fakes import FakeClock
from tests.unit.sim.wire import (
    REF_50,
    START,
    ask,
    control,
    drive,
    fc_line,
    frames_in,
    read,
    transact,
)


@pytest.mark.parametrize(
    ("baudrate", "parity", "stopbits", "bits"),
    [(9600, "E", 1, 11), (19200, "E", 1, 11), (115200, "E", 1, 11), (19200, "N", 1, 10),
     (19200, "N", 2, 11), (38400, "O", 2, 12)],
)  # fmt: skip
def test_reply_arrives_after_request_delay_and_reply_on_the_wire(
    baudrate: int, parity: str, stopbits: int, bits: int
) -> None:
    clock = FakeClock()
    line = build_line(
        LineSettings(baudrate=baudrate, parity=parity, stopbits=stopbits),
        [(1, DriveSettings())],
        clock=clock,
    )
    written = clock.now()
    line.write(encode_telegram(read(1, 1613)))
    due = line.next_delivery()
    assert due is not None
    assert due == pytest.approx(written + (16 + 16) * bits / baudrate + 0.010, abs=1e-9)
    clock.time = due - 1e-6
    assert line.receive() == b""  # not one microsecond early
    clock.time = due
    assert len(line.receive()) == 16


def test_response_delay_is_the_drive_8_35() -> None:
    clock = FakeClock()
    line = fc_line(clock, (1,), settings=DriveSettings(response_delay_s=0.050))
    line.write(encode_telegram(control(1, START)))
    assert line.next_delivery() == pytest.approx(clock.now() + 16 * 11 / 19200 + 0.050)


def test_only_the_addressed_drive_answers_and_copies_the_adr_byte() -> None:
    clock = FakeClock()
    line = fc_line(clock, (1, 2, 3))
    reply = ask(line, clock, control(2, START, REF_50))
    assert reply.address == 2
    assert transact(line, clock, control(9, START)) == b""  # nobody at 9
    short = ask(line, clock, Telegram(address=3, address_format=AddressFormat.FORMAT_31))
    assert short.address_format is AddressFormat.FORMAT_31
    assert drive(line, 2).motor.output_on
    assert not drive(line, 1).motor.output_on
    assert not drive(line, 3).motor.output_on


@pytest.mark.parametrize("address_format", list(AddressFormat))
def test_broadcast_is_obeyed_by_every_drive_and_never_answered(
    address_format: AddressFormat,
) -> None:
    clock = FakeClock()
    line = fc_line(clock, (1, 2, 3))
    broadcast = Telegram(address=0, address_format=address_format, pcd1=START, pcd2=REF_50)
    line.write(encode_telegram(broadcast))
    assert line.next_delivery() is None
    assert all(drive(line, a).motor.output_on for a in (1, 2, 3))
    assert line.counters.requests == 1
    assert line.counters.replies == 0


def test_master_bytes_written_while_its_previous_bytes_are_out_queue_behind_them() -> None:
    clock = FakeClock()
    line = fc_line(clock, (1, 2))
    char = 11 / 19200
    line.write(encode_telegram(control(0, START)))  # broadcast: 8 characters, no reply
    line.write(encode_telegram(control(2, START)))  # same instant: starts after the first
    record = line.transactions[-1]
    assert record.request_end == pytest.approx(clock.now() + 16 * char)
    assert record.reply_end == pytest.approx(clock.now() + 24 * char + 0.010)


def test_request_during_a_reply_collides_and_garbles_both() -> None:
    clock = FakeClock()
    line = fc_line(clock, (1, 2))
    line.write(encode_telegram(read(1, 1613)))
    first = line.transactions[-1]
    assert first.reply_start is not None
    clock.time = first.reply_start + 0.001  # the reply is on the wire
    line.write(encode_telegram(read(2, 1613)))
    arrived = b""
    while (due := line.next_delivery()) is not None:
        clock.time = due
        arrived += line.receive()
    assert len(arrived) == 16  # the garbled first reply; drive 2 never heard a valid request
    assert frames_in(arrived) == []
    assert line.counters.collisions == 1
    assert "collision" in first.faults
    assert line.counters.requests == 1  # the second request was not a valid frame


def test_request_that_ends_before_the_pending_reply_starts_does_not_collide() -> None:
    clock = FakeClock()
    line = fc_line(clock, (1, 2))
    line.write(encode_telegram(control(1, START)))
    clock.time = line.transactions[-1].request_end + 0.001  # inside drive 1's response delay
    line.write(encode_telegram(control(2, START)))
    arrived = b""
    while (due := line.next_delivery()) is not None:
        clock.time = due
        arrived += line.receive()
    assert [frame[2] for frame in frames_in(arrived)] == [0x81, 0x82]
    assert line.counters.collisions == 0


def test_a_pause_inside_a_request_makes_the_drives_drop_it() -> None:
    clock = FakeClock()
    line = fc_line(clock, (1,))
    request = encode_telegram(control(1, START))
    line.write(request[:5])
    clock.time += line.wire_s(5) + line.gap_s + 0.001
    line.write(request[5:])
    assert line.next_delivery() is None
    assert line.counters.skipped_bytes == len(request)
    assert transact(line, clock, request) != b""  # the next whole request is answered


def test_a_request_written_in_pieces_within_the_gap_is_heard_whole() -> None:
    clock = FakeClock()
    line = fc_line(clock, (1,))
    request = encode_telegram(control(1, START))
    line.write(request[:3])
    clock.time += 0.001
    line.write(request[3:])
    assert line.transactions[-1].request_at == clock.now() - 0.001
    assert line.next_delivery() is not None


def test_echo_returns_the_master_bytes_at_their_wire_time_before_the_reply() -> None:
    clock = FakeClock()
    line = fc_line(clock, (1,), faults=FaultPlan(echo=True))
    request = encode_telegram(control(1, START))
    line.write(request)
    assert line.next_delivery() == pytest.approx(clock.now() + 8 * 11 / 19200)
    arrived = transact(line, clock, b"")
    assert arrived[:8] == request
    assert frames_in(arrived[8:])[0][2] == 0x81


def test_transactions_record_request_arrival_and_reply_delivery() -> None:
    clock = FakeClock()
    line = fc_line(clock, (1,))
    transact(line, clock, control(1, START))
    clock.time += 0.002
    at = clock.now()
    transact(line, clock, read(1, 1613))
    record = line.transactions[-1]
    assert record.request_at == at
    assert record.address == 1
    assert record.reply_length == 16
    assert record.reply_end == clock.now()
    before = line.transactions[-2].reply_end
    assert before is not None
    gap = record.request_at - before
    assert gap == pytest.approx(0.002)


def test_history_is_bounded() -> None:
    clock = FakeClock()
    line = SimLine(
        drives=[], framer_factory=FcFramer, baudrate=19200, char_bits=11, clock=clock, history=3
    )
    for _ in range(5):
        line.write(encode_telegram(control(0, START)))
    assert len(line.transactions) == 3


def test_fault_plans_for_absent_drives_are_refused() -> None:
    with pytest.raises(UsageError, match="without a drive"):
        SimLine(
            drives=[], framer_factory=FcFramer, baudrate=19200, char_bits=11,
            clock=FakeClock(), drive_faults={4: FaultPlan(drop=1.0)},
        )  # fmt: skip


def test_a_reply_to_the_first_telegram_of_a_burst_garbles_the_rest_of_it() -> None:
    clock = FakeClock()
    line = fc_line(clock, (1, 2), baudrate=2400)  # 16 bytes last 73 ms; the delay is 10 ms
    line.write(encode_telegram(read(1, 1613)) + encode_telegram(read(2, 1613)))
    assert line.counters.requests == 1  # drive 2's telegram was garbled by drive 1's reply
    assert line.counters.collisions == 1
    assert frames_in(transact(line, clock, b"")) == []
