"""Replay rules for Modbus RTU: reads by their question, writes acknowledged anew."""

from __future__ import annotations

from fcmaster.protocol.modbus_rtu.crc import with_crc
from fcmaster.protocol.modbus_rtu.frame import (
    Function,
    ReadRequest,
    Registers,
    WriteMultiple,
    WriteSingle,
    encode_request,
    encode_response,
)
from fcmaster.sim.modbus_rtu.replay import RULES, address, answer, question

READ = encode_request(ReadRequest(address=3, function=Function.READ_HOLDING, start=1, count=2))
READ_REPLY = encode_response(Registers(address=3, function=Function.READ_HOLDING, values=(7, 8)))


def test_a_read_is_asked_by_drive_function_and_span_and_a_write_by_none() -> None:
    other_span = encode_request(
        ReadRequest(address=3, function=Function.READ_HOLDING, start=1, count=3)
    )
    assert question(READ) is not None
    assert question(READ) != question(other_span)
    assert question(encode_request(WriteSingle(address=3, register=0, value=6))) is None
    assert question(b"\x03\x03") is None  # not a request


def test_a_write_of_any_value_is_acknowledged_as_the_drive_would() -> None:
    write = encode_request(WriteSingle(address=3, register=0, value=0x0F))
    assert answer(write, READ_REPLY) == write  # FC 6: the request itself comes back
    multiple = encode_request(WriteMultiple(address=3, start=0, values=(0x0F, 2500)))
    # FC 16: address, function, start and count, then the CRC
    assert answer(multiple, READ_REPLY) == with_crc(bytes.fromhex("031000000002"))


def test_a_read_never_captured_and_a_broadcast_get_nothing_made_up() -> None:
    assert answer(READ, READ_REPLY) is None
    broadcast = encode_request(WriteSingle(address=0, register=0, value=6))
    assert answer(broadcast, READ_REPLY) is None
    assert address(broadcast) is None
    assert address(READ) == address(READ_REPLY) == 3


def test_the_rules_cut_requests_out_of_the_masters_bytes() -> None:
    framer = RULES.framer()
    framer.feed(READ + encode_request(WriteSingle(address=3, register=0, value=6)))
    first, second = framer.next_frame(), framer.next_frame()
    assert first is not None
    assert first.data == READ
    assert second is not None
    assert second.data[:2] == b"\x03\x06"
