"""The pipe's messages between the daemon and its OPC UA server process."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.opcua.wire import Decoder, WireError, encode

json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(), inner, max_size=4),
    max_leaves=10,
)  # fmt: skip


@given(
    messages=st.lists(st.dictionaries(st.text(), json_values, max_size=4), max_size=5),
    cut=st.integers(min_value=1, max_value=7),
)
def test_messages_come_out_whole_and_in_order_however_the_bytes_are_cut(
    messages: list[dict[str, Any]], cut: int
) -> None:
    sent = [{**m, "t": "drives"} for m in messages]
    data = b"".join(encode(m) for m in sent)
    decoder = Decoder()
    received: list[dict[str, Any]] = []
    for start in range(0, len(data), cut):
        received += decoder.feed(data[start : start + cut])
    assert received == sent


def test_one_message_is_one_line_of_compact_json() -> None:
    assert encode({"t": "call", "id": 1, "user": "ops"}) == b'{"t":"call","id":1,"user":"ops"}\n'
    with pytest.raises(ValueError, match="JSON compliant"):
        encode({"t": "drives", "f": float("nan")})  # NaN is no JSON: never sent


@pytest.mark.parametrize(
    "line", [b"not json\n", b"[1, 2]\n", b'{"kind": "drives"}\n', b'{"t": 3}\n']
)
def test_a_line_that_is_no_message_breaks_the_pipe(line: bytes) -> None:
    with pytest.raises(WireError):
        Decoder().feed(line)


def test_a_line_without_end_is_bounded() -> None:
    decoder = Decoder(max_line=16)
    assert decoder.feed(b"x" * 16) == []
    with pytest.raises(WireError, match="longer than 16"):
        decoder.feed(b"x")
