"""Adoption of an FC drive found ramping (status bit 8 = 0): what it executes decides.

A scripted FC drive reports itself running off its reference, with the control word it
executes in 16-00. The master must read that first and command exactly it: a stop it is
ramping down on, or running at its present output when it executes motion, or when it
cannot tell (no valid word, no such parameter, the read lost).
"""

from __future__ import annotations

import pytest

from fcmaster.bus.plan import DrivePlan
from fcmaster.protocol.danfoss_fc import StatusWord
from fcmaster.protocol.danfoss_fc.error_codes import ILLEGAL_PARAMETER
from tests.fakes import Timed
from tests.unit.bus.bench import IGNORED, RUN_WORD, STOP_WORD, T0, bench
from tests.unit.bus.fcdrive import FcDrive, FcLine

A = DrivePlan(name="a", address=1, control=True)
COAST_WORD = 0x0474


class Ramping(FcDrive):
    """Running off its reference at 30 %, executing ``executed`` (16-00), until told otherwise."""

    def __init__(self, executed: int) -> None:
        super().__init__(1, running=True, output_pct=30.0)
        self.parameters[1600] = executed

    @property
    def status_word(self) -> int:
        return super().status_word & ~StatusWord.AT_REFERENCE  # still ramping


def commanded(b: object, address: int = 1) -> list[int]:
    """The valid control words the master sent (the ignored ones left out)."""
    words: list[int] = b.words(address)  # type: ignore[attr-defined]
    return [w for w in words if w != IGNORED]


@pytest.mark.parametrize(
    ("executed", "adopted"),
    [
        pytest.param(STOP_WORD, STOP_WORD, id="ramp-stop"),
        pytest.param(COAST_WORD, COAST_WORD, id="coast"),
        pytest.param(RUN_WORD, RUN_WORD, id="run"),
        pytest.param(0x0000, RUN_WORD, id="no-valid-word"),
    ],
)
async def test_a_drive_off_its_reference_is_adopted_as_its_executed_word_says(
    executed: int, adopted: int
) -> None:
    drive = Ramping(executed)
    b = bench(A, fc=[drive])
    async with b.master:
        await b.clock.run_until(T0 + 0.5)
    reads = [t.pnu for _, t in b.requests(1) if t.pke is not None]
    assert 1600 in reads[:3]  # asked first, before the rest of the monitor list
    words = commanded(b)
    assert words, "never adopted"
    assert set(words) == {adopted}
    first_valid = next(i for i, (_, t) in enumerate(b.requests(1)) if t.pcd1 != IGNORED)
    assert 1600 in [t.pnu for _, t in b.requests(1)[:first_valid]]  # read before commanding


async def test_a_drive_without_16_00_is_adopted_by_its_status() -> None:
    drive = Ramping(STOP_WORD)
    drive.errors[1600] = ILLEGAL_PARAMETER
    b = bench(A, fc=[drive])
    async with b.master:
        await b.clock.run_until(T0 + 0.5)
    assert set(commanded(b)) == {RUN_WORD}  # nothing to say otherwise: kept at its output


async def test_a_lost_read_of_16_00_is_asked_again() -> None:
    drive = Ramping(STOP_WORD)
    line = FcLine(drive)
    lost: list[int] = []

    def respond(request: bytes) -> bytes | Timed | None:
        if request[3:5] == b"\x16\x40" and not lost:  # the first read of 16-00 (PKE 0x1640)
            lost.append(1)
            return None
        return line(request)

    b = bench(A, fc=[drive], responder=respond)
    async with b.master:
        await b.clock.run_until(T0 + 1.0)
    assert lost
    assert set(commanded(b)) == {STOP_WORD}


async def test_a_drive_in_local_operation_is_adopted_by_its_status() -> None:
    drive = Ramping(STOP_WORD)  # the bus's last word, which local operation ignores
    drive.local = True
    b = bench(A, fc=[drive])
    async with b.master:
        await b.clock.run_until(T0 + 0.5)
    assert 1600 not in [t.pnu for _, t in b.requests(1)]
    assert set(commanded(b)) == {RUN_WORD}
