"""A tiny Danfoss FC drive for bus tests, built on the codec's own telegram encoder.

Just enough of a VLT to answer a master: it obeys control words with bit 10 set (start,
stop, coast, quick stop, jog, reverse, reset on the rising edge of bit 7), reports its
status word and main actual value, and answers parameter reads and writes from a table,
with AK 7 for parameters it does not have. It reaches its reference at once.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from fcmaster.protocol.danfoss_fc import (
    ControlWord,
    ResponseAk,
    StatusWord,
    Telegram,
    decode_reference,
    decode_telegram,
    encode_reference,
    encode_telegram,
    lookup,
    make_pke,
)
from fcmaster.protocol.danfoss_fc.error_codes import ILLEGAL_PARAMETER

READY = StatusWord.CONTROL_READY | StatusWord.DRIVE_READY | StatusWord.ENABLED
JOG_PCT = 10.0
_READS = (0x1,)
_WRITES = {0x2: False, 0x3: True, 0xD: True, 0xE: False}  # AK → double word


def default_parameters() -> dict[int, int]:
    """Raw values of the default monitor list and a few settings (16-13 raw 503 = 50.3 Hz)."""
    return {
        1613: 503,
        1614: 1234,
        1612: 4000,
        1610: 75,
        1630: 560,
        1690: 0,
        1692: 0,
        341: 500,
        342: 500,
        1500: 12,
    }


@dataclass
class FcDrive:
    """One simulated FC drive at ``address``."""

    address: int
    running: bool = False
    output_pct: float = 0.0  # negative: turning in reverse
    tripped: bool = False
    warning: bool = False
    local: bool = False  # local operation: bus control words are ignored
    silent: bool = False  # answers nothing (powered off, wrong address, broken wire)
    parameters: dict[int, int] = field(default_factory=default_parameters)
    errors: dict[int, int] = field(default_factory=dict)  # PNU → AK 7 error code
    received: list[Telegram] = field(default_factory=list)
    _last_ctw: int = 0

    @property
    def status_word(self) -> int:
        word = READY
        if not self.local:
            word |= StatusWord.BUS_CONTROL
        if self.running:
            word |= StatusWord.RUNNING | StatusWord.AT_REFERENCE
        if self.tripped:
            word |= StatusWord.TRIP
        if self.warning:
            word |= StatusWord.WARNING
        return int(word)

    def trip(self) -> None:
        """A fault: the output switches off and the status word shows a trip."""
        self.tripped, self.running, self.output_pct = True, False, 0.0

    def handle(self, request: Telegram) -> Telegram | None:
        """Act on ``request``; the reply, or None for a broadcast or a silent drive."""
        self.received.append(request)
        if self.silent:
            return None
        self._control(request.pcd1, request.pcd2)
        if request.is_broadcast:
            return None
        reply = Telegram(
            address=self.address,
            pcd1=self.status_word,
            pcd2=encode_reference(self.output_pct),
        )
        if request.pke is None:
            return reply
        return self._parameter(request, reply)

    def _control(self, ctw: int, ref: int) -> None:
        if not ctw & ControlWord.DATA_VALID or self.local:
            return
        rising = ctw & ~self._last_ctw
        self._last_ctw = ctw
        if rising & ControlWord.RESET:
            self.tripped = False
        moving = ctw & ControlWord.START and ctw & ControlWord.NO_COAST
        moving = moving and ctw & ControlWord.NO_QUICK_STOP
        if self.tripped or not moving:
            self.running, self.output_pct = False, 0.0
            return
        pct = JOG_PCT if ctw & ControlWord.JOG else decode_reference(ref)
        self.running = True
        self.output_pct = -pct if ctw & ControlWord.REVERSE else pct

    def _parameter(self, request: Telegram, reply: Telegram) -> Telegram:
        pnu, ak = request.pnu, request.ak
        if pnu in self.errors or pnu not in self.parameters:
            code = self.errors.get(pnu, ILLEGAL_PARAMETER)
            return _with(reply, ResponseAk.ERROR, pnu, request.ind, code)
        spec = lookup(pnu)
        if ak in _WRITES:
            self.parameters[pnu] = spec.raw_from_pwe(request.pwe, double_word=_WRITES[ak])
        elif ak not in _READS:
            return _with(reply, ResponseAk.ERROR, pnu, request.ind, 253)
        raw = self.parameters[pnu]
        if spec.is_double_word:
            return _with(reply, ResponseAk.VALUE_DWORD, pnu, request.ind, raw & 0xFFFF_FFFF)
        return _with(reply, ResponseAk.VALUE_WORD, pnu, request.ind, raw & 0xFFFF)


def _with(reply: Telegram, ak: int, pnu: int, ind: int, pwe: int) -> Telegram:
    return Telegram(
        address=reply.address,
        pcd1=reply.pcd1,
        pcd2=reply.pcd2,
        pke=make_pke(ak, pnu),
        ind=ind,
        pwe=pwe,
    )


class FcLine:
    """A multi-drop line of :class:`FcDrive` s: a responder for ScriptedTransport."""

    def __init__(self, *drives: FcDrive) -> None:
        self.drives = {drive.address: drive for drive in drives}

    def __call__(self, request: bytes) -> bytes | None:
        telegram = decode_telegram(request, from_drive=False)
        if telegram.is_broadcast:
            for drive in self.drives.values():
                drive.handle(telegram)
            return None
        target = self.drives.get(telegram.address)
        if target is None:
            return None
        reply = target.handle(telegram)
        return None if reply is None else encode_telegram(reply)
