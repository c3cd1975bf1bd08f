"""Hypothesis strategies for ENC frames, shared by the codec tests.

The checksum here is the test's own oracle (protocols/enc.md §3.1: the sum of the ASCII
codes between ``~`` and the checksum, as four uppercase hex digits), not the codec's.
"""

from __future__ import annotations

from hypothesis import strategies as st

from fcmaster.protocol.enc import Request, Response

HEX = "0123456789ABCDEF"

fields = st.integers(0, 0xFF)
words = st.integers(0, 0xFFFF)


def ascii_sum(text: str) -> int:
    """The §3.1 sum, written out independently of the codec."""
    total = 0
    for character in text:
        total += ord(character)
    return total


def close(body: str) -> bytes:
    """``~`` + body + the hand-rule checksum + CR."""
    return ("~" + body + format(ascii_sum(body), "04X") + "\r").encode("ascii")


requests = st.builds(
    Request,
    address=fields,
    command=fields,
    aux_index=fields,
    cmd_index=fields,
    data=st.none() | words,
)


@st.composite
def responses(draw: st.DrawFn) -> Response:
    """Any response: bare (frame error), with index area, or with index and data areas."""
    shape = draw(st.sampled_from(("bare", "index", "data")))
    address, response = draw(fields), draw(fields)
    if shape == "bare":
        return Response(address=address, response=response)
    return Response(
        address=address,
        response=response,
        failure_index=draw(fields),
        cmd_index=draw(fields),
        data=draw(words) if shape == "data" else None,
    )


hex_bodies = st.sampled_from((4, 8, 12)).flatmap(
    lambda n: st.text(alphabet=HEX, min_size=n, max_size=n)
)
checked_frames = hex_bodies.map(close)  # well-formed frames with any content
