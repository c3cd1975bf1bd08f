"""The RTU codec against the Modbus specifications' worked examples, and round trips.

The examples: the CRC example of Modbus over Serial Line V1.02 (frame 02 07 has CRC 0x1241,
sent 41 12), and the request/response PDUs of the Application Protocol V1.1b3 for 03 (§6.3,
registers 108-110), 04 (§6.4, register 9), 06 (§6.6, register 2 := 3), 16 (§6.12, registers
2-3 := 000A 0102) and an exception (§7, function 01 refused with code 02).
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.errors import MalformedReply, UsageError
from fcmaster.protocol.modbus_rtu import (
    ExceptionCode,
    ExceptionReply,
    Function,
    ReadRequest,
    Registers,
    Request,
    Response,
    WriteMultiple,
    WriteSingle,
    Written,
    crc16,
    crc_ok,
    decode_request,
    decode_response,
    encode_request,
    encode_response,
    exception_text,
    reply_length,
    with_crc,
)
from tests.unit.protocol.modbus_rtu.strategies import (
    bitwise_crc,
    request_wires,
    requests,
    response_wires,
    responses,
)

SERVER = 0x11


def rtu(address: int, pdu: str) -> bytes:
    """An RTU frame around a PDU written as in the specification, CRC by the test's oracle."""
    body = bytes((address,)) + bytes.fromhex(pdu)
    crc = bitwise_crc(body)
    return body + bytes((crc & 0xFF, crc >> 8))


# ---------------------------------------------------------------- the CRC


def test_crc_of_the_serial_line_example() -> None:
    assert crc16(b"\x02\x07") == 0x1241
    assert with_crc(b"\x02\x07") == b"\x02\x07\x41\x12"  # low byte first


def test_a_frame_with_its_crc_checks_and_one_flipped_bit_does_not() -> None:
    frame = with_crc(b"\x02\x07")
    assert crc_ok(frame)
    assert not crc_ok(b"\x02\x06\x41\x12")
    assert not crc_ok(b"\x02\x07\x12\x41")  # high byte first is wrong


@given(st.binary(max_size=300))
def test_table_crc_agrees_with_the_bitwise_definition(data: bytes) -> None:
    assert crc16(data) == bitwise_crc(data)


# ---------------------------------------------------------------- the specification's examples

EXAMPLES: list[tuple[str, Request, str, Response, str]] = [
    (
        "03",
        ReadRequest(address=SERVER, function=Function.READ_HOLDING, start=0x6B, count=3),
        "03 006B 0003",
        Registers(address=SERVER, function=Function.READ_HOLDING, values=(0x022B, 0, 0x64)),
        "03 06 022B 0000 0064",
    ),
    (
        "04",
        ReadRequest(address=SERVER, function=Function.READ_INPUT, start=0x08, count=1),
        "04 0008 0001",
        Registers(address=SERVER, function=Function.READ_INPUT, values=(0x000A,)),
        "04 02 000A",
    ),
    (
        "06",
        WriteSingle(address=SERVER, register=1, value=3),
        "06 0001 0003",
        WriteSingle(address=SERVER, register=1, value=3),
        "06 0001 0003",
    ),
    (
        "16",
        WriteMultiple(address=SERVER, start=1, values=(0x000A, 0x0102)),
        "10 0001 0002 04 000A 0102",
        Written(address=SERVER, start=1, count=2),
        "10 0001 0002",
    ),
]


@pytest.mark.parametrize(
    ("request_", "request_pdu", "response", "response_pdu"),
    [example[1:] for example in EXAMPLES],
    ids=[example[0] for example in EXAMPLES],
)
def test_the_application_protocol_examples(
    request_: Request, request_pdu: str, response: Response, response_pdu: str
) -> None:
    request_wire = rtu(SERVER, request_pdu)
    response_wire = rtu(SERVER, response_pdu)
    assert encode_request(request_) == request_wire
    assert decode_request(request_wire) == request_
    assert encode_response(response) == response_wire
    assert decode_response(response_wire) == response
    assert reply_length(request_) == len(response_wire)


def test_the_exception_example() -> None:
    wire = rtu(SERVER, "81 02")
    reply = ExceptionReply(address=SERVER, function=0x01, code=ExceptionCode.ILLEGAL_DATA_ADDRESS)
    assert encode_response(reply) == wire
    assert decode_response(wire) == reply
    assert len(wire) == 5


def test_a_widely_printed_frame() -> None:
    # Read one holding register at 2 from server 1: 01 03 00 02 00 01 25 CA.
    request = ReadRequest(address=1, function=Function.READ_HOLDING, start=2, count=1)
    assert encode_request(request).hex(" ") == "01 03 00 02 00 01 25 ca"


@pytest.mark.parametrize(
    ("code", "words"),
    [(1, "function"), (2, "address"), (3, "value"), (4, "failure"), (6, "busy"), (11, "respond")],
)
def test_exception_texts(code: int, words: str) -> None:
    assert words in exception_text(code).lower()


def test_an_unknown_exception_code_is_named_by_number() -> None:
    assert "77" in exception_text(77)


# ---------------------------------------------------------------- broadcast


def test_a_broadcast_write_gets_no_reply() -> None:
    write = WriteSingle(address=0, register=256, value=0x047F)
    assert reply_length(write) == 0
    assert encode_request(write)[0] == 0
    assert reply_length(WriteMultiple(address=0, start=0, values=(1, 2))) == 0


def test_a_read_cannot_be_broadcast() -> None:
    with pytest.raises(UsageError, match="broadcast"):
        encode_request(ReadRequest(address=0, function=Function.READ_HOLDING, start=0, count=1))


# ---------------------------------------------------------------- refusals


@pytest.mark.parametrize(
    ("request_", "match"),
    [
        (ReadRequest(address=248, function=Function.READ_HOLDING, start=0, count=1), "0-247"),
        (ReadRequest(address=1, function=Function.READ_HOLDING, start=0, count=126), "1-125"),
        (ReadRequest(address=1, function=Function.READ_INPUT, start=0, count=0), "1-125"),
        (ReadRequest(address=1, function=Function.READ_INPUT, start=0xFFFF, count=2), "past"),
        (WriteSingle(address=1, register=0, value=0x10000), "16-bit"),
        (WriteSingle(address=1, register=-1, value=0), "16-bit"),
        (WriteMultiple(address=1, start=0, values=(0,) * 124), "1-123"),
        (WriteMultiple(address=1, start=0, values=()), "1-123"),
    ],
)
def test_requests_beyond_the_specification_are_refused(request_: Request, match: str) -> None:
    with pytest.raises(UsageError, match=match):
        encode_request(request_)


@pytest.mark.parametrize(
    ("wire", "match"),
    [
        (rtu(1, "03 03 0001 00"), "byte count"),
        (rtu(1, "03 04 0001"), "byte count"),
        (rtu(1, "06 0001"), "4 data bytes"),
        (rtu(1, "81 02 03"), "one code byte"),
        (rtu(1, "05 0001 FF00"), "not a register function"),
        (b"\x01\x03\x02\x00\x01\x00\x00", "CRC"),
        (b"\x01\x83", "too short"),
    ],
)
def test_malformed_responses_are_refused_not_guessed(wire: bytes, match: str) -> None:
    with pytest.raises(MalformedReply, match=match):
        decode_response(wire)


def test_malformed_write_multiple_request() -> None:
    with pytest.raises(MalformedReply, match="disagree"):
        decode_request(rtu(1, "10 0001 0002 02 000A"))


# ---------------------------------------------------------------- round trips


@given(requests)
def test_requests_round_trip(request_: Request) -> None:
    wire = encode_request(request_)
    assert decode_request(wire) == request_
    assert bitwise_crc(wire[:-2]) == int.from_bytes(wire[-2:], "little")


@given(responses)
def test_responses_round_trip(response: Response) -> None:
    assert decode_response(encode_response(response)) == response


@given(request_wires)
def test_request_wires_decode_and_encode_back(wire: bytes) -> None:
    assert encode_request(decode_request(wire)) == wire


@given(response_wires)
def test_response_wires_decode_and_encode_back(wire: bytes) -> None:
    assert encode_response(decode_response(wire)) == wire
