"""Hypothesis strategies for FC telegrams, shared by the codec tests.

Generated telegrams are always *consistent*: the wire format has one documented ambiguity
(protocols/danfoss-fc.md §5.1, §6.4) — a text block of four characters is as long as a
parameter block — and ``decode_telegram`` settles it by direction. So:

* from a drive, AK F is always text, so a parameter block never carries AK F;
* from the master, a four-character text block is text only with IND high byte 0x05
  ("write text"), so such texts get that IND, and a parameter block with AK F never does.
"""

from __future__ import annotations

from functools import reduce
from operator import xor

from hypothesis import strategies as st

from fcmaster.protocol.danfoss_fc import AddressFormat, Telegram

MAX_TEXT = 245  # LGE is one byte: 10 + n <= 255
IND_WRITE_TEXT_HIGH = 0x05

words = st.integers(min_value=0, max_value=0xFFFF)
pnus = st.integers(min_value=0, max_value=0xFFF)
pwes = st.integers(min_value=0, max_value=0xFFFF_FFFF)


def xor_all(data: bytes) -> int:
    """The test's own BCC oracle: XOR of every byte (not the codec's ``bcc``)."""
    return reduce(xor, data, 0)


def close_with_bcc(body: bytes) -> bytes:
    """Append the byte that makes the XOR of the whole frame zero."""
    return body + bytes((xor_all(body),))


addresses = st.one_of(
    st.tuples(st.integers(0, 31), st.just(AddressFormat.FORMAT_31)),
    st.tuples(st.integers(0, 126), st.just(AddressFormat.FORMAT_126)),
)


@st.composite
def telegrams(draw: st.DrawFn, *, from_drive: bool, max_text_length: int = MAX_TEXT) -> Telegram:
    """Any consistent telegram of any kind in the given direction."""
    address, address_format = draw(addresses)
    pcd1, pcd2 = draw(words), draw(words)
    kind = draw(st.sampled_from(("process", "parameter", "text")))
    if kind == "process":
        return Telegram(address=address, address_format=address_format, pcd1=pcd1, pcd2=pcd2)
    pnu = draw(pnus)
    if kind == "parameter":
        ak = draw(st.integers(0, 0xE) if from_drive else st.integers(0, 0xF))
        ind = draw(words)
        if ak == 0xF and ind >> 8 == IND_WRITE_TEXT_HIGH:
            ind ^= 0x0100  # any other high byte: a request with AK F is then not text
        return Telegram(
            address=address, address_format=address_format, pcd1=pcd1, pcd2=pcd2,
            pke=ak << 12 | pnu, ind=ind, pwe=draw(pwes),
        )  # fmt: skip
    text = draw(st.binary(max_size=max_text_length))
    ind = draw(words)
    if len(text) == 4 and not from_drive:
        ind = IND_WRITE_TEXT_HIGH << 8 | ind & 0xFF
    return Telegram(
        address=address, address_format=address_format, pcd1=pcd1, pcd2=pcd2,
        pke=0xF000 | pnu, ind=ind, text=text,
    )  # fmt: skip


@st.composite
def directed_telegrams(
    draw: st.DrawFn, *, max_text_length: int = MAX_TEXT
) -> tuple[Telegram, bool]:
    """``(telegram, from_drive)`` for either direction."""
    from_drive = draw(st.booleans())
    return draw(telegrams(from_drive=from_drive, max_text_length=max_text_length)), from_drive


@st.composite
def checked_frames(draw: st.DrawFn) -> bytes:
    """STX, a plausible LGE, random content and a right BCC: frames that reach deep."""
    lge = draw(st.sampled_from((6, 14)) | st.integers(0, 0xFF))
    content = draw(st.binary(min_size=lge - 1, max_size=lge - 1)) if lge else b""
    return close_with_bcc(bytes((0x02, lge)) + content)[: lge + 2]
