"""Replaying FC drives: the question a telegram asks, and a status answer built anew.

Every FC request carries the master's control word and reference (PCD1, PCD2) beside its
question (PKE, IND, and PWE for a write). What a drive answers depends on the question and on
its state, not on the words the master commands, so a capture of a daemon that commanded its
drives also answers a commissioning tool whose control word is 0, or a daemon adopting the
drives with the control word marked not valid. A telegram that asks no parameter (a process
block, or AK 0) is answered with the drive's latest status word and actual value.
"""

from __future__ import annotations

from collections.abc import Hashable

from fcmaster.errors import MalformedReply, UsageError
from fcmaster.protocol.danfoss_fc.framer import FcFramer
from fcmaster.protocol.danfoss_fc.telegram import (
    RequestAk,
    Telegram,
    decode_telegram,
    encode_telegram,
)
from fcmaster.sim.simulator import ReplayRules

# AKs whose PWE is a value written: part of the question
_WRITES = frozenset(
    (RequestAk.WRITE_WORD, RequestAk.WRITE_DWORD, RequestAk.WRITE_WORD_EEPROM,
     RequestAk.WRITE_DWORD_EEPROM, RequestAk.TEXT)
)  # fmt: skip


def _telegram(frame: bytes, *, from_drive: bool) -> Telegram | None:
    try:
        return decode_telegram(frame, from_drive=from_drive)
    except (MalformedReply, UsageError):
        return None


def question(request: bytes) -> Hashable | None:
    """The telegram without its control word and reference: address and parameter part."""
    asked = _telegram(request, from_drive=False)
    if asked is None:
        return None
    value = asked.pwe if asked.ak in _WRITES else None
    return (asked.address, asked.address_format, asked.pke, asked.ind, value, asked.text)


def address(frame: bytes) -> int | None:
    """The drive a telegram is for or from (None: not a telegram, or a broadcast)."""
    telegram = _telegram(frame, from_drive=False) or _telegram(frame, from_drive=True)
    return telegram.address if telegram is not None and telegram.address else None


def answer(request: bytes, reply: bytes) -> bytes | None:
    """``request`` answered with ``reply``'s status word and actual value, if it asks no more."""
    asked, said = _telegram(request, from_drive=False), _telegram(reply, from_drive=True)
    if asked is None or said is None or asked.pke not in (None, 0) or not asked.address:
        return None  # a parameter the capture never answered: the replay cannot know it
    return encode_telegram(
        Telegram(
            address=asked.address,
            address_format=asked.address_format,
            pcd1=said.pcd1,
            pcd2=said.pcd2,
            pke=asked.pke,  # None (process block) or 0: no parameter answered
        )
    )


RULES = ReplayRules(framer=FcFramer, question=question, address=address, answer=answer)
