"""Helpers for sim tests: a line of FC drives in virtual time, and one transaction on it."""

from __future__ import annotations

from fcmaster.clock import Clock
from fcmaster.protocol.danfoss_fc import (
    FcFramer,
    Telegram,
    decode_telegram,
    encode_telegram,
    make_pke,
)
from fcmaster.protocol.framing import Frame
from fcmaster.sim import DriveSettings, FaultPlan, FcSimDrive, LineSettings, SimLine, build_line
from tests.fakes import FakeClock

START = 0x047C  # §8.3 typical control words
STOP = 0x043C
COAST = 0x0474
QUICK_STOP = 0x046C
RESET = 0x04FC
JOG = 0x057C
REVERSE = 0x847C
RAMP_2 = 0x067C
FREEZE = 0x045C
IGNORED = 0x0000
REF_100 = 0x4000
REF_50 = 0x2000


def frames_in(data: bytes) -> list[bytes]:
    """The checked frames in ``data`` (noise and broken frames left out)."""
    framer = FcFramer()
    framer.feed(data)
    found = []
    while (piece := framer.next_frame()) is not None:
        if isinstance(piece, Frame):
            found.append(piece.data)
    return found


def fc_line(
    clock: Clock,
    addresses: tuple[int, ...] = (1, 2, 3),
    *,
    baudrate: int = 19200,
    parity: str = "E",
    faults: FaultPlan | None = None,
    settings: DriveSettings | None = None,
) -> SimLine:
    return build_line(
        LineSettings(baudrate=baudrate, parity=parity, faults=faults or FaultPlan()),
        [(address, settings or DriveSettings()) for address in addresses],
        clock=clock,
    )


def drive(line: SimLine, address: int) -> FcSimDrive:
    found = next(d for d in line.drives if d.address == address)
    assert isinstance(found, FcSimDrive)
    return found


def transact(line: SimLine, clock: FakeClock, request: Telegram | bytes) -> bytes:
    """Write ``request`` now, move the clock to the end of the reply, return what arrived."""
    line.write(request if isinstance(request, bytes) else encode_telegram(request))
    out = b""
    while (due := line.next_delivery()) is not None:
        clock.time = max(clock.time, due)
        out += line.receive()
    return out


def ask(line: SimLine, clock: FakeClock, request: Telegram) -> Telegram:
    """One clean transaction; the decoded reply."""
    return decode_telegram(transact(line, clock, request), from_drive=True)


def control(address: int, ctw: int, ref: int = 0) -> Telegram:
    return Telegram(address=address, pcd1=ctw, pcd2=ref)


def read(address: int, pnu: int, *, ind: int = 0, ctw: int = IGNORED, ref: int = 0) -> Telegram:
    return Telegram(address=address, pcd1=ctw, pcd2=ref, pke=make_pke(0x1, pnu), ind=ind)


def write(address: int, pnu: int, pwe: int, *, ak: int = 0x2, ind: int = 0) -> Telegram:
    return Telegram(address=address, pke=make_pke(ak, pnu), ind=ind, pwe=pwe)
