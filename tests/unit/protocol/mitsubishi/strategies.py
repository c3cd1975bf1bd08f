"""Hypothesis strategies for computer-link messages, shared by the codec tests.

Generated messages are always valid ones: a read request carries no data and a code
00-7F, a write carries 2, 4, 6 or 10 digits and a code 80-FF, a model-name reply carries
20 printable characters. A drive's NAK always has an error code; the master's never.
"""

from __future__ import annotations

from hypothesis import strategies as st

from fcmaster.protocol.mitsubishi import Ack, DataReply, Message, Nak, Request, Terminator

stations = st.integers(0, 31)
terminators = st.sampled_from(list(Terminator))
wait_times_on = st.integers(0, 15).map(lambda digit: digit * 10)
wait_times = st.none() | wait_times_on


def ascii_sum(chars: bytes) -> str:
    """The test's own sum-check oracle: two uppercase hex digits of the low byte of the sum."""
    total = 0
    for char in chars:
        total += char
    return f"{total % 256:02X}"


TWO_DIGIT_WRITES = (0xFA, 0xF3, 0xFF, 0xEC)  # §9, hand-copied: not the framer's own table


def width_of(instruction: int, draw: st.DrawFn) -> int:
    """The data width the instruction code fixes (§9): what a drive's framer expects."""
    if instruction < 0x80:
        return 0
    if instruction == 0xF0:
        return 10
    if instruction in TWO_DIGIT_WRITES:
        return 2
    return draw(st.sampled_from((4, 6)))


@st.composite
def requests(draw: st.DrawFn, *, wait: bool | None = None, by_code: bool = False) -> Request:
    """Any valid request; ``wait`` forces the waiting-time digit in or out.

    With ``by_code`` the data width is the one the instruction code fixes; otherwise any
    width goes with any write code (the frame format allows it).
    """
    station = draw(stations)
    wait_ms = draw(wait_times if wait is None else st.just(None) if not wait else wait_times_on)
    if draw(st.booleans()):
        return Request(station=station, instruction=draw(st.integers(0, 0x7F)), wait_ms=wait_ms)
    instruction = draw(st.integers(0x80, 0xFF))
    width = width_of(instruction, draw) if by_code else draw(st.sampled_from((2, 4, 6, 10)))
    return Request(
        station=station,
        instruction=instruction,
        data=draw(st.integers(0, 16**width - 1)),
        width=width,
        wait_ms=wait_ms,
    )


text_20 = st.text(st.characters(min_codepoint=0x20, max_codepoint=0x7E), min_size=20, max_size=20)


@st.composite
def data_replies(draw: st.DrawFn) -> DataReply:
    """Any valid read reply, the model name included."""
    station = draw(stations)
    width = draw(st.sampled_from((2, 4, 6, 12, 20)))
    if width == 20:
        return DataReply(station=station, data=None, width=20, text=draw(text_20))
    return DataReply(station=station, data=draw(st.integers(0, 16**width - 1)), width=width)


drive_naks = st.builds(Nak, stations, st.integers(0, 15))
replies: st.SearchStrategy[Message] = st.one_of(
    data_replies(), st.builds(Ack, stations), drive_naks
)
master_messages: st.SearchStrategy[Message] = st.one_of(
    requests(), st.builds(Ack, stations), st.builds(Nak, stations)
)
master_answers: st.SearchStrategy[Message] = st.builds(Ack, stations) | st.builds(Nak, stations)
messages: st.SearchStrategy[Message] = replies | master_messages
