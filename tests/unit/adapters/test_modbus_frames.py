"""Modbus TCP framing: the bytes of the specification's examples, and any bytes at all."""

from __future__ import annotations

import struct

from hypothesis import given
from hypothesis import strategies as st

from fcmaster.adapters.modbus_frames import (
    Broken,
    ExceptionCode,
    Function,
    MbapFramer,
    Refusal,
    Request,
    encode_exception,
    encode_registers,
    encode_written,
)


def items(framer: MbapFramer) -> list[Request | Refusal | Broken]:
    out = []
    while (item := framer.next_item()) is not None:
        out.append(item)
    return out


def test_a_read_input_registers_request_and_its_answer() -> None:
    # Application Protocol §6.4's example (input register 9, one register) in an MBAP.
    framer = MbapFramer()
    framer.feed(bytes.fromhex("1234 0000 0006 11 04 0008 0001"))
    (request,) = items(framer)
    assert request == Request(
        transaction=0x1234, unit=0x11, function=Function.READ_INPUT, address=8, count=1
    )
    assert encode_registers(request, [0x000A]) == bytes.fromhex("1234 0000 0005 11 04 02 000A")


def test_writes_are_answered_as_the_specification_says() -> None:
    framer = MbapFramer()
    framer.feed(bytes.fromhex("0001 0000 0006 01 06 0001 0003"))
    framer.feed(bytes.fromhex("0002 0000 000b 01 10 0000 0002 04 000A 0102"))
    single, multiple = items(framer)
    assert isinstance(single, Request)
    assert isinstance(multiple, Request)
    assert single.values == (3,)
    assert multiple.values == (0x000A, 0x0102)
    assert encode_written(single) == bytes.fromhex("0001 0000 0006 01 06 0001 0003")
    assert encode_written(multiple) == bytes.fromhex("0002 0000 0006 01 10 0000 0002")


def test_an_exception_sets_the_high_bit_of_the_function() -> None:
    answer = encode_exception(7, 3, 6, ExceptionCode.GATEWAY_TARGET_FAILED)
    assert answer == bytes.fromhex("0007 0000 0003 03 86 0B")


def test_a_header_with_another_protocol_id_breaks_the_stream_for_good() -> None:
    framer = MbapFramer()
    framer.feed(bytes.fromhex("0001 0002 0006 01 04 0000 0001"))
    (broken,) = items(framer)
    assert isinstance(broken, Broken)
    framer.feed(bytes.fromhex("0001 0000 0006 01 04 0000 0001"))
    assert framer.next_item() is None  # nothing after a broken header is trusted


def frames() -> st.SearchStrategy[bytes]:
    """Well-formed headers around any PDU."""
    return st.builds(
        lambda t, u, pdu: struct.pack(">HHHB", t, 0, len(pdu) + 1, u) + pdu,
        st.integers(0, 0xFFFF),
        st.integers(0, 0xFF),
        st.binary(min_size=1, max_size=253),
    )


@given(st.lists(frames(), max_size=6), st.data())
def test_whole_frames_in_any_chunks_give_one_item_each(
    stream: list[bytes], data: st.DataObject
) -> None:
    joined = b"".join(stream)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(joined)), max_size=8)))
    framer = MbapFramer()
    got: list[Request | Refusal | Broken] = []
    for start, end in zip([0, *cuts], [*cuts, len(joined)], strict=True):
        framer.feed(joined[start:end])
        got.extend(items(framer))
    assert len(got) == len(stream)
    assert not [item for item in got if isinstance(item, Broken)]
    for frame, item in zip(stream, got, strict=True):
        assert item.transaction == struct.unpack_from(">H", frame)[0]  # type: ignore[union-attr]
    assert framer.pending == 0


@given(st.binary(max_size=600))
def test_any_bytes_never_raise_and_never_pile_up(data: bytes) -> None:
    framer = MbapFramer()
    for byte in data:
        framer.feed(bytes((byte,)))
        items(framer)
        assert framer.pending < 7 + 254  # at most one unfinished frame is held
