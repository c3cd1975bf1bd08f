"""Replaying Modbus RTU drives: the question a request asks, and a write acknowledged anew.

A master writes a drive's control word (and reference) as values; what the drive answers a
write is the write itself (FC 6) or the span written (FC 16), whatever the values. So a
capture of a daemon that commanded its drives also answers a daemon adopting them afresh or
a commissioning tool writing other values: a write is acknowledged for any drive the
capture heard, and a read gets what the same read got in the capture (its registers' values
then). A read the capture never holds, and a drive never heard, stay unanswered.
"""

from __future__ import annotations

from collections.abc import Hashable

from fcmaster.errors import MalformedReply, ProtocolError, UsageError
from fcmaster.protocol.modbus_rtu.frame import (
    ReadRequest,
    Request,
    WriteMultiple,
    WriteSingle,
    Written,
    decode_request,
    decode_response,
    encode_response,
)
from fcmaster.protocol.modbus_rtu.framer import Direction, RtuFramer
from fcmaster.sim.simulator import ReplayRules


def _request(frame: bytes) -> Request | None:
    try:
        return decode_request(frame)
    except (MalformedReply, ProtocolError, UsageError):
        return None


def question(request: bytes) -> Hashable | None:
    """A read's drive, function and span; None for a write, which :func:`answer` answers.

    A write is acknowledged anew, never with a captured echo of other values.
    """
    asked = _request(request)
    if isinstance(asked, ReadRequest):
        return (asked.address, int(asked.function), asked.start, asked.count)
    return None


def address(frame: bytes) -> int | None:
    """The drive a request or reply is for or from (None: not a frame, or a broadcast)."""
    asked = _request(frame)
    if asked is not None:
        return asked.address or None
    try:
        return decode_response(frame).address or None
    except (MalformedReply, ProtocolError, UsageError):
        return None


def answer(request: bytes, reply: bytes) -> bytes | None:
    """A write acknowledged as the drive acknowledges any write; None for anything else."""
    asked = _request(request)
    match asked:
        case WriteSingle() if asked.address:
            return encode_response(asked)
        case WriteMultiple(address=drive, start=start, values=values) if drive:
            return encode_response(Written(address=drive, start=start, count=len(values)))
    return None


RULES = ReplayRules(
    framer=lambda: RtuFramer(Direction.REQUESTS),
    question=question,
    address=address,
    answer=answer,
)
