"""Hypothesis strategies for Modbus RTU frames, and the test's own CRC oracle."""

from __future__ import annotations

from hypothesis import strategies as st

from fcmaster.protocol.modbus_rtu import (
    ExceptionReply,
    Function,
    ReadRequest,
    Registers,
    WriteMultiple,
    WriteSingle,
    Written,
    encode_request,
    encode_response,
)

words = st.integers(0, 0xFFFF)
servers = st.integers(1, 247)


def bitwise_crc(data: bytes) -> int:
    """The CRC as Serial Line §6.2.2 describes it, bit by bit: independent of the codec."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            lsb = crc & 1
            crc >>= 1
            if lsb:
                crc ^= 0xA001
    return crc


@st.composite
def spans(draw: st.DrawFn, most: int) -> tuple[int, int]:
    count = draw(st.integers(1, most))
    return draw(st.integers(0, 0x10000 - count)), count


@st.composite
def read_requests(draw: st.DrawFn) -> ReadRequest:
    start, count = draw(spans(125))
    function = draw(st.sampled_from((Function.READ_HOLDING, Function.READ_INPUT)))
    return ReadRequest(address=draw(servers), function=function, start=start, count=count)


@st.composite
def write_multiples(draw: st.DrawFn) -> WriteMultiple:
    start, count = draw(spans(123))
    values = tuple(draw(st.lists(words, min_size=count, max_size=count)))
    return WriteMultiple(address=draw(st.integers(0, 247)), start=start, values=values)


write_singles = st.builds(WriteSingle, address=st.integers(0, 247), register=words, value=words)
requests = read_requests() | write_singles | write_multiples()


@st.composite
def written(draw: st.DrawFn) -> Written:
    start, count = draw(spans(123))
    return Written(address=draw(servers), start=start, count=count)


registers = st.builds(
    Registers,
    address=servers,
    function=st.sampled_from((Function.READ_HOLDING, Function.READ_INPUT)),
    values=st.lists(words, min_size=1, max_size=125).map(tuple),
)
exceptions = st.builds(
    ExceptionReply,
    address=servers,
    function=st.sampled_from(tuple(Function)),
    code=st.integers(0, 0xFF),
)
responses = (
    registers
    | st.builds(WriteSingle, address=servers, register=words, value=words)
    | written()
    | exceptions
)
request_wires = requests.map(encode_request)
response_wires = responses.map(encode_response)
