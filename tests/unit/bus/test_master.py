"""BusMaster in virtual time: the bytes it writes, when it writes them, and what it reports.

Every test runs a real BusMaster against a scripted line of tiny FC drives
(``tests/unit/bus/fcdrive.py``) on a :class:`~tests.fakes.VirtualClock`; nothing sleeps in
real time, and times are asserted exactly.
"""

from __future__ import annotations

import itertools
import random

import pytest
import structlog.testing

from fcmaster.bus.commands import Action, Command, Outcome
from fcmaster.bus.master import BACKOFF_FIRST_S, BACKOFF_MAX_S
from fcmaster.bus.plan import DrivePlan, OnStart
from fcmaster.protocol.danfoss_fc import (
    ControlWord,
    RequestAk,
    StatusWord,
    encode_reference,
    make_pke,
)
from fcmaster.protocol.drive import ControlIntent, Motion
from tests.fakes import Timed
from tests.orders import orders
from tests.unit.bus.bench import (
    CHAR_S,
    IGNORED,
    PARAMETER,
    PAUSE_S,
    PROCESS,
    RESET_STOP_WORD,
    RUN_WORD,
    STOP_WORD,
    T0,
    Bench,
    bench,
    delayed,
    exchange_s,
    reply_frame,
)
from tests.unit.bus.fcdrive import FcDrive, FcLine

A = DrivePlan(name="a", address=1, control=True)  # under bus control
B = DrivePlan(name="b", address=2, control=True)
M = DrivePlan(name="m", address=3)  # monitor only
POLL_S = exchange_s(PARAMETER, PARAMETER)


def approx(value: float) -> object:
    return pytest.approx(value, abs=1e-9)


def check_half_duplex(b: Bench) -> None:
    """Each request goes out exactly when the one before it has ended, never earlier.

    Ended: its reply arrived and the pause passed, or its deadline passed and a late reply
    would have finished arriving; a broadcast ends when the drives have had time to act.
    """
    plan = b.plan
    sent = b.transport.sent
    for before, after in itertools.pairwise(sent):
        length = len(before.data)
        # The deadline the master read until (it follows the line once replies are timed).
        deadline = before.deadline or before.at + plan.reply_timeout(length, length)
        if before.data[2] == 0x80:  # broadcast
            end = before.at + plan.wire_s(length) + plan.response_delay_s + PAUSE_S
        elif before.reply_at is not None and before.reply_at <= deadline:
            end = before.reply_at + PAUSE_S
        else:
            end = deadline + plan.wire_s(length) + plan.gap_s
        assert after.at == approx(end), f"request at {after.at - T0:.6f} s"


# -- timing and the half-duplex rule -----------------------------------------------------


async def test_first_request_at_start_and_next_one_exactly_pause_after_reply() -> None:
    b = bench(M, pause_s=0.003)
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
    sent = b.transport.sent
    assert sent[0].at == T0
    assert sent[1].at == approx(T0 + 32 * 11 / 19200 + 0.010 + 0.003)
    assert sent[1].at == approx((sent[0].reply_at or 0.0) + 0.003)
    assert sent[2].at == approx(sent[1].at + POLL_S + 0.003)


async def test_default_pause_is_two_character_times_from_the_reply() -> None:
    b = bench(M)
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
    sent = b.transport.sent
    assert len(sent) > 3
    for before, after in itertools.pairwise(sent):
        assert after.at == approx((before.reply_at or 0.0) + 2 * 11 / 19200)


async def test_never_two_requests_in_flight_with_slow_and_silent_drives_and_commands() -> None:
    a, slow, dead = FcDrive(1), FcDrive(2), FcDrive(4, silent=True)
    line = FcLine(a, slow, dead)
    b = bench(
        A,
        DrivePlan(name="slow", address=2, control=True),
        DrivePlan(name="dead", address=4, control=True),
        fc=[a, slow, dead],
        responder=delayed(line, 2, 0.045),
        probe_interval_s=0.3,
    )
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        drive = orders(b.master, "a")
        b.submit(drive.start(frequency_hz=20))
        b.submit(orders(b.master, "slow").read("16-14"))
        await b.clock.run_until(T0 + 0.5)
        b.submit(drive.stop())
        b.submit(b.master.execute(None, Command(action=Action.STOP)))
        b.submit(drive.read("16-13"))
        await b.clock.run_until(T0 + 1.5)
    assert all(task.result().outcome is Outcome.DONE for task in b.tasks)
    assert len(b.transport.sent) > 30
    check_half_duplex(b)


async def test_every_online_drive_polled_in_turn() -> None:
    b = bench(A, B, M)
    async with b.master:
        await b.clock.run_until(T0 + 0.5)
    addresses = [t.address for _, t in b.requests()]
    assert addresses[:12] == [1, 2, 3] * 4
    counts = [addresses.count(n) for n in (1, 2, 3)]
    assert max(counts) - min(counts) <= 1


def last_reply_at(b: Bench, name: str) -> float:
    """When drive ``name`` last answered."""
    return max(at for who, _, at, _ in b.observer.replies if who == name)


async def test_silent_drive_leaves_the_round_once_demoted() -> None:
    b = bench(A, M, fc=[FcDrive(1), FcDrive(3)], offline_after=2)
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        b.drives[3].silent = True  # it answered, then fell silent
        await b.clock.run_until(T0 + 0.6)
    addresses = [t.address for at, t in b.requests() if at > last_reply_at(b, "m")]
    assert addresses[:4] == [1, 3, 1, 3]
    assert set(addresses[4:]) == {1}
    assert b.observer.availability[-1][:2] == ("m", False)


async def test_a_drive_never_heard_gets_one_poll_then_waits_for_its_probe() -> None:
    b = bench(A, M, fc=[FcDrive(1), FcDrive(3, silent=True)], offline_after=2)
    async with b.master:
        await b.clock.run_until(T0 + 0.6)
    addresses = [t.address for _, t in b.requests()]
    assert addresses[:2] == [1, 3]
    assert set(addresses[2:]) == {1}  # its probe is due only after the probe interval
    assert [(n, online) for n, online, _ in b.observer.availability] == [
        ("a", True),
        ("m", False),
    ]


async def test_idle_polls_read_the_monitor_list_in_rotation() -> None:
    b = bench(DrivePlan(name="m", address=3, monitor=("16-13", "16-30")))
    async with b.master:
        await b.clock.run_until(T0 + 0.15)
    requests = [t for _, t in b.requests()]
    assert [t.pnu for t in requests[:5]] == [1613, 1630, 1613, 1630, 1613]
    assert {t.ak for t in requests} == {RequestAk.READ}
    values = [reply.value for _, reply, _, _ in b.observer.replies[:2]]
    assert [(v.value, v.unit) for v in values if v is not None] == [(50.3, "Hz"), (560.0, "V")]


async def test_empty_monitor_list_polls_with_process_telegrams() -> None:
    b = bench(DrivePlan(name="m", address=3, monitor=()))
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
    assert {len(s.data) for s in b.transport.sent} == {PROCESS}
    assert b.transport.sent[1].at == approx(T0 + exchange_s(PROCESS, PROCESS) + PAUSE_S)


async def test_drive_updates_are_handed_on_after_the_next_request_is_written() -> None:
    b = bench(M)
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
    count = len(b.observer.replies)
    assert count >= 3
    # the reply to request k is reported once request k + 1 is on the wire
    assert b.observer.replied_after_writes == [k + 2 for k in range(count)]
    assert [at for _, _, at, _ in b.observer.replies] == [
        approx(s.reply_at or 0.0) for s in b.transport.sent[:count]
    ]


# -- commands: order, coalescing, superseding ------------------------------------------


async def test_command_is_the_very_next_request_after_the_one_in_flight() -> None:
    b = bench(A, M)
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        in_flight = await b.mid_transaction()
        count = len(b.transport.sent)
        result = await b.complete(b.submit(orders(b.master, "a").read("16-14")))
    assert result.outcome is Outcome.DONE
    command = b.transport.sent[count]
    assert command.at == approx((in_flight.reply_at or 0.0) + PAUSE_S)
    assert command.data[2] == 0x81
    assert b.requests()[count][1].pnu == 1614


async def test_urgent_stop_overtakes_commands_queued_before_it() -> None:
    b = bench(A, M)
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        await b.mid_transaction()
        count = len(b.transport.sent)
        drive = orders(b.master, "a")
        read = b.submit(drive.read("16-13"))
        write = b.submit(orders(b.master, "m").read("3-41"))  # a monitor drive may be read
        stop = b.submit(drive.coast())
        for task in (read, write, stop):
            await b.complete(task)
    assert [t.result().outcome for t in (read, write, stop)] == [Outcome.DONE] * 3
    after = [t for _, t in b.requests()[count : count + 3]]
    assert [(t.address, t.pnu) for t in after] == [(1, 0), (1, 1613), (3, 341)]
    assert after[0].pcd1 == 0x0474  # coast: bit 3 = 0
    assert after[1].pcd1 == 0x0474  # the read carries the coast word too


async def test_queued_references_coalesce_and_the_newest_wins() -> None:
    b = bench(A, M, fc=[FcDrive(1, running=True, output_pct=50.0), FcDrive(3)])
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        await b.mid_transaction()
        drive = orders(b.master, "a")
        with structlog.testing.capture_logs() as logs:
            tasks = [b.submit(drive.set_reference(reference_pct=pct)) for pct in (20.0, 30.0, 40.0)]
            for task in tasks:
                await b.complete(task)
            await b.clock.run_for(0.2)
    assert [t.result().outcome for t in tasks] == [
        Outcome.SUPERSEDED,
        Outcome.SUPERSEDED,
        Outcome.DONE,
    ]
    assert [t.result().reason for t in tasks[:2]] == [
        "superseded by set_reference 30 %",
        "superseded by set_reference 40 %",
    ]
    audit = [
        (e["reference_pct"], e["frequency_hz"], e["outcome"])
        for e in logs
        if e["event"] == "command.completed"
    ]
    assert audit == [(20.0, 10.0, "superseded"), (30.0, 15.0, "superseded"), (40.0, 20.0, "done")]
    references = {t.pcd2 for _, t in b.requests(1)}
    assert encode_reference(40.0) in references
    assert not {encode_reference(20.0), encode_reference(30.0)} & references
    assert b.drives[1].output_pct == pytest.approx(40.0, abs=0.01)


async def test_stop_cancels_queued_start_jog_and_reference_of_that_drive_only() -> None:
    b = bench(A, B)
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        await b.mid_transaction()
        drive = orders(b.master, "a")
        start = b.submit(drive.start(reference_pct=30.0))
        jog = b.submit(drive.jog())
        reference = b.submit(drive.set_reference(reference_pct=25.0))
        read = b.submit(drive.read("16-13"))
        other = b.submit(orders(b.master, "b").start(reference_pct=10.0))
        stop = b.submit(drive.stop())
        await b.complete(other)
    for task in (start, jog, reference):
        result = task.result()
        assert result.outcome is Outcome.SUPERSEDED
        assert result.reason == "superseded by stop"
    assert [t.result().outcome for t in (read, other, stop)] == [Outcome.DONE] * 3
    assert not [w for w in b.words(1) if w & ControlWord.START]
    assert b.drives[2].running
    assert not b.drives[1].running


async def test_stop_while_start_is_on_the_wire_lets_the_start_finish_then_stops() -> None:
    b = bench(A)
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        drive = orders(b.master, "a")
        start = b.submit(drive.start(reference_pct=50.0))
        in_flight = await b.mid_transaction()
        while b.requests()[-1][1].pcd1 != RUN_WORD:
            in_flight = await b.mid_transaction()
            await b.clock.run_for(0.001)
        stop = b.submit(drive.stop())
        await b.complete(stop)
        await b.complete(start)
        await b.clock.run_for(0.1)
    assert start.result().outcome is Outcome.DONE  # it was on the wire: the drive acted on it
    assert stop.result().outcome is Outcome.DONE
    after = [(at, t.pcd1) for at, t in b.requests() if at > in_flight.at]
    assert after[0] == (approx((in_flight.reply_at or 0.0) + PAUSE_S), STOP_WORD)
    assert {word for _, word in after} == {STOP_WORD}
    assert not b.drives[1].running


async def test_reference_while_reference_is_on_the_wire_goes_out_after_it() -> None:
    b = bench(A, fc=[FcDrive(1, running=True, output_pct=50.0)])
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        drive = orders(b.master, "a")
        first = b.submit(drive.set_reference(reference_pct=20.0))
        await b.mid_transaction()
        while b.requests()[-1][1].pcd2 != encode_reference(20.0):
            await b.clock.run_for(0.001)
            await b.mid_transaction()
        second = b.submit(drive.set_reference(reference_pct=30.0))
        await b.complete(second)
        await b.complete(first)
        await b.clock.run_for(0.1)
    assert first.result().outcome is Outcome.DONE
    assert second.result().outcome is Outcome.DONE
    assert b.requests()[-1][1].pcd2 == encode_reference(30.0)
    assert b.drives[1].output_pct == pytest.approx(30.0, abs=0.01)


# -- control words -----------------------------------------------------------------------


async def test_monitor_only_drive_gets_an_ignored_control_word_in_every_telegram() -> None:
    b = bench(M, fc=[FcDrive(3, running=True, output_pct=50.0)])
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        drive = orders(b.master, "m")
        read = await b.complete(b.submit(drive.read("16-13")))
        results = [
            await b.complete(b.submit(call))
            for call in (
                drive.start(reference_pct=10.0),
                drive.stop(),
                drive.coast(),
                drive.reset(),
                drive.jog(),
                drive.set_reference(reference_pct=5.0),
            )
        ]
        await b.clock.run_for(0.1)
    assert read.outcome is Outcome.DONE
    assert {r.outcome for r in results} == {Outcome.NOT_ALLOWED}
    assert "monitor-only" in results[0].reason
    assert {(t.pcd1, t.pcd2) for _, t in b.requests()} == {(IGNORED, 0)}
    assert b.drives[3].running


@pytest.mark.parametrize(
    ("output_pct", "word", "reference"),
    [
        pytest.param(37.5, RUN_WORD, 0x1800, id="forward"),
        pytest.param(-25.0, RUN_WORD | ControlWord.REVERSE, 0x1000, id="reverse"),
    ],
)
async def test_adopting_a_running_drive_keeps_it_running_at_its_present_output(
    output_pct: float, word: int, reference: int
) -> None:
    b = bench(A, fc=[FcDrive(1, running=True, output_pct=output_pct)])
    async with b.master:
        await b.clock.run_until(T0 + 0.3)
    requests = [t for _, t in b.requests()]
    assert (requests[0].pcd1, requests[0].pcd2) == (IGNORED, 0)
    assert {(t.pcd1, t.pcd2) for t in requests[1:]} == {(word, reference)}
    assert b.drives[1].running
    assert b.drives[1].output_pct == output_pct


async def test_adopting_a_stopped_drive_commands_a_stop_word() -> None:
    b = bench(A)
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
    words = b.words(1)
    assert words[0] == IGNORED
    assert set(words[1:]) == {STOP_WORD}


async def test_on_start_stop_sends_a_stop_word_from_the_first_telegram() -> None:
    plan = DrivePlan(name="a", address=1, control=True, on_start=OnStart.STOP)
    b = bench(plan, fc=[FcDrive(1, running=True, output_pct=50.0)])
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
    assert set(b.words(1)) == {STOP_WORD}
    assert not b.drives[1].running


async def test_start_sends_run_word_and_reference_and_every_later_telegram_repeats_them() -> None:
    b = bench(A)
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        count = len(b.transport.sent)
        result = await b.complete(b.submit(orders(b.master, "a").start(frequency_hz=25.0)))
        await b.clock.run_for(0.3)
    assert result.outcome is Outcome.DONE
    later = [t for _, t in b.requests()[count:]]
    assert len(later) > 5
    assert {(t.pcd1, t.pcd2) for t in later} == {(RUN_WORD, 0x2000)}  # 25 of 50 Hz
    assert b.drives[1].running


async def test_reference_beyond_max_frequency_is_refused_and_never_sent() -> None:
    plan = DrivePlan(name="a", address=1, control=True, max_frequency_hz=40.0)
    b = bench(plan)
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        drive = orders(b.master, "a")
        start = await b.complete(b.submit(drive.start(frequency_hz=45.0)))
        reference = await b.complete(b.submit(drive.set_reference(frequency_hz=-41.0)))
        await b.clock.run_for(0.1)
    assert start.outcome is Outcome.NOT_ALLOWED
    assert reference.outcome is Outcome.NOT_ALLOWED
    assert "limit of 40 Hz" in start.reason
    assert set(b.words(1)[1:]) == {STOP_WORD}
    assert {t.pcd2 for _, t in b.requests(1)} == {0}


async def test_a_negative_reference_is_invalid_and_never_sent() -> None:
    # Direction changes only by forward or reverse: -5 Hz within the limits is no reverse run.
    b = bench(DrivePlan(name="a", address=1, control=True, max_frequency_hz=50.0))
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        drive = orders(b.master, "a")
        start = await b.complete(b.submit(drive.start(frequency_hz=-5.0)))
        reference = await b.complete(b.submit(drive.set_reference(reference_pct=-20.0)))
        await b.clock.run_for(0.1)
    assert start.outcome is Outcome.INVALID
    assert reference.outcome is Outcome.INVALID
    assert "forward or reverse" in start.reason
    assert set(b.words(1)[1:]) == {STOP_WORD}
    assert {t.pcd2 for _, t in b.requests(1)} == {0}
    assert not b.drives[1].running


async def test_trip_turns_the_intent_into_a_stop_so_a_reset_does_not_restart() -> None:
    b = bench(A, fc=[FcDrive(1, running=True, output_pct=50.0)])
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        tripped_at = b.clock.now()
        b.drives[1].trip()
        await b.clock.run_for(0.2)
        count = len(b.transport.sent)
        result = await b.complete(b.submit(orders(b.master, "a").reset()))
        await b.clock.run_for(0.2)
    assert result.outcome is Outcome.DONE
    after_trip = [t.pcd1 for at, t in b.requests() if at > tripped_at]
    assert after_trip[0] == RUN_WORD  # written before any reply showed the trip
    assert set(after_trip[1 : count - len(b.transport.sent)]) == {STOP_WORD}
    assert not b.drives[1].tripped
    assert not b.drives[1].running


async def test_reset_is_a_one_telegram_pulse_of_bit_7() -> None:
    b = bench(A, fc=[FcDrive(1, tripped=True)])
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        count = len(b.transport.sent)
        result = await b.complete(b.submit(orders(b.master, "a").reset()))
        await b.clock.run_for(0.1)
    assert result.outcome is Outcome.DONE
    words = [t.pcd1 for _, t in b.requests()[count:]]
    assert words[0] == RESET_STOP_WORD
    assert set(words[1:]) == {STOP_WORD}
    assert not b.drives[1].tripped


async def test_drive_in_local_operation_leaves_a_start_unconfirmed_and_refuses_a_reference() -> (
    None
):
    b = bench(A, fc=[FcDrive(1, local=True)])
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        drive = orders(b.master, "a")
        started = await b.complete(b.submit(drive.start(reference_pct=10.0)))
        referred = await b.complete(b.submit(drive.set_reference(reference_pct=20.0)))
    assert started.outcome is Outcome.UNCONFIRMED
    assert "local operation" in started.reason
    assert referred.outcome is Outcome.REFUSED
    assert "local operation" in referred.reason
    assert not b.drives[1].running


# -- parameters --------------------------------------------------------------------------


async def test_parameter_read_returns_the_scaled_value() -> None:
    b = bench(A)
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        count = len(b.transport.sent)
        result = await b.complete(b.submit(orders(b.master, "a").read("16-13")))
    assert result.outcome is Outcome.DONE
    assert result.value is not None
    assert (result.value.value, result.value.unit, result.value.raw) == (50.3, "Hz", 503)
    request = b.requests()[count][1]
    assert (request.pke, request.ind, request.pcd1) == (
        make_pke(RequestAk.READ, 1613),
        0,
        STOP_WORD,
    )


@pytest.mark.parametrize(
    ("persist", "ak"),
    [
        pytest.param(False, RequestAk.WRITE_DWORD, id="ram"),
        pytest.param(True, RequestAk.WRITE_DWORD_EEPROM, id="eeprom"),
    ],
)
async def test_parameter_write_sends_the_raw_value(persist: bool, ak: RequestAk) -> None:
    b = bench(A)
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        count = len(b.transport.sent)
        drive = orders(b.master, "a")
        result = await b.complete(b.submit(drive.write("3-41", 7.5, persist=persist)))
    assert result.outcome is Outcome.DONE
    assert result.value is not None
    assert (result.value.value, result.value.unit) == (7.5, "s")
    request = b.requests()[count][1]
    assert (request.ak, request.pnu, request.pwe) == (ak, 341, 750)
    assert b.drives[1].parameters[341] == 750


async def test_drive_error_ak_7_ends_refused_with_the_drives_error_code() -> None:
    b = bench(A, fc=[FcDrive(1, errors={1500: 130})])
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        result = await b.complete(b.submit(orders(b.master, "a").read("15-00")))
    assert result.outcome is Outcome.REFUSED
    assert result.error is not None
    assert (result.error.code, result.error.text) == (130, "No bus access for this parameter")
    assert "130" in result.reason
    assert b.master.stats.drives["a"].refused == 1


# -- what comes back: wrong address, malformed, noise, gaps, late replies --------------


async def _first_reply(pieces: tuple[tuple[float, bytes], ...]) -> Bench:
    drive = FcDrive(3)
    line = FcLine(drive)
    calls = 0

    def respond(request: bytes) -> bytes | Timed | None:
        nonlocal calls
        calls += 1
        reply = line(request)
        return Timed(pieces) if calls == 1 else reply

    b = bench(M, fc=[drive], responder=respond)
    async with b.master:
        await b.clock.run_until(T0 + 0.3)
    return b


def good_reply() -> bytes:
    return reply_frame(3, 0x0207, pke=make_pke(1, 1613), pwe=503)


async def test_reply_from_another_address_is_counted_and_the_right_reply_still_taken() -> None:
    b = await _first_reply(((0.020, reply_frame(5, pke=make_pke(1, 1613))), (0.040, good_reply())))
    stats = b.master.stats
    assert stats.unexpected == 1
    assert stats.timeouts == 0
    assert b.observer.replies[0][2] == approx(T0 + 0.040)
    assert b.transport.sent[1].at == approx(T0 + 0.040 + PAUSE_S)


def malformed_frame() -> bytes:
    # LGE 11 is a one-character text block, but AK is 1: a checked frame that cannot decode
    body = bytes((0x02, 11, 0x83, 0x16, 0x4D, 0, 0)) + b"X" + bytes((0x02, 0x07, 0, 0))
    bcc = 0
    for byte in body:
        bcc ^= byte
    return body + bytes((bcc,))


async def test_malformed_frame_is_counted_and_the_master_waits_on_for_the_reply() -> None:
    b = await _first_reply(((0.020, malformed_frame()), (0.050, good_reply())))
    assert b.master.stats.malformed == 1
    assert b.master.stats.timeouts == 0
    assert b.transport.sent[1].at == approx(T0 + 0.050 + PAUSE_S)


async def test_only_a_malformed_frame_means_a_timeout_at_the_deadline() -> None:
    b = await _first_reply(((0.020, malformed_frame()),))
    plan = b.plan
    deadline = T0 + plan.reply_timeout(PARAMETER, PARAMETER)
    assert b.master.stats.malformed == 1
    assert b.master.stats.timeouts == 1
    assert b.transport.sent[1].at == approx(deadline + plan.wire_s(PARAMETER) + plan.gap_s)


async def test_noise_before_the_reply_is_counted_and_the_reply_accepted() -> None:
    b = await _first_reply(((0.030, b"\xff\x00\x13" + good_reply()),))
    assert b.master.stats.noise_bytes == 3
    assert b.observer.replies[0][2] == approx(T0 + 0.030)
    assert b.transport.sent[1].at == approx(T0 + 0.030 + PAUSE_S)


async def test_reply_split_by_less_than_the_gap_is_taken_whole() -> None:
    reply = good_reply()
    b = await _first_reply(((0.020, reply[:5]), (0.0215, reply[5:])))
    assert b.master.stats.noise_bytes == 0
    assert b.observer.replies[0][2] == approx(T0 + 0.0215)


async def test_reply_split_by_an_inter_character_gap_is_dropped() -> None:
    reply = good_reply()
    b = await _first_reply(((0.020, reply[:5]), (0.023, reply[5:])))  # gap_s is 2.005 ms
    plan = b.plan
    deadline = T0 + plan.reply_timeout(PARAMETER, PARAMETER)
    stats = b.master.stats
    assert (stats.noise_bytes, stats.timeouts, stats.replies > 0) == (len(reply), 1, True)
    assert b.observer.replies[0][2] > deadline  # the first reply taken is the second poll's
    assert b.transport.sent[1].at == approx(deadline + plan.wire_s(PARAMETER) + plan.gap_s)


async def test_late_reply_is_discarded_and_not_taken_for_the_next_one() -> None:
    drive = FcDrive(3)
    b = bench(M, fc=[drive], responder=delayed(FcLine(drive), 3, 0.085), offline_after=99)
    async with b.master:
        await b.clock.run_until(T0 + 0.5)
    plan = b.plan
    deadline = plan.reply_timeout(PARAMETER, PARAMETER)
    assert T0 + deadline < (b.transport.sent[0].reply_at or 0.0)  # it is late indeed
    stats = b.master.stats
    assert stats.replies == 0
    assert stats.timeouts == len(b.transport.sent) - 1
    assert stats.late_bytes == PARAMETER * stats.timeouts
    assert b.observer.replies == []
    assert b.observer.availability == []
    check_half_duplex(b)


# -- line loss and reopening -------------------------------------------------------------


async def test_line_loss_cancels_queued_commands_reports_the_line_down_and_reopens() -> None:
    b = bench(A, B, seed=7)
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        in_flight = await b.mid_transaction()
        b.transport.lost = True
        queued = [
            b.submit(orders(b.master, "a").start(reference_pct=10.0)),
            b.submit(orders(b.master, "b").read("16-13")),
        ]
        lost_at = in_flight.reply_at or 0.0
        await b.clock.run_until(lost_at)
        assert not b.master.is_up
        while_down = await b.complete(b.submit(orders(b.master, "a").stop()))
        await b.clock.run_for(1.0)
        assert b.master.is_up
    for task in queued:
        result = task.result()
        assert result.outcome is Outcome.CANCELLED
        assert result.reason == "line1 lost its port: scripted line loss"
    assert while_down.outcome is Outcome.CANCELLED
    assert while_down.reason == "line1 is down: scripted line loss"
    backoff = BACKOFF_FIRST_S * (0.8 + 0.4 * random.Random(7).random())
    assert b.observer.lines == [
        (True, "", T0),
        (False, "scripted line loss", approx(lost_at)),
        (True, "", approx(lost_at + backoff)),
    ]
    assert {(n, online) for n, online, _ in b.observer.availability if not online} == {
        ("a", False),
        ("b", False),
    }
    assert b.transport.open_attempts == [T0, approx(lost_at + backoff)]
    assert b.master.stats.reopens == 1
    assert b.transport.sent[len(b.transport.sent) - 1].at > lost_at + backoff
    first_after = next(s for s in b.transport.sent if s.at > lost_at)
    assert first_after.at == approx(lost_at + backoff)


async def test_drive_that_stopped_while_the_line_was_down_is_not_restarted() -> None:
    b = bench(A, fc=[FcDrive(1, running=True, output_pct=50.0)])
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        in_flight = await b.mid_transaction()
        b.transport.lost = True
        await b.clock.run_until(in_flight.reply_at or 0.0)
        b.drives[1].running, b.drives[1].output_pct = False, 0.0  # its watchdog stopped it
        lost_at = b.clock.now()
        await b.clock.run_for(1.0)
    words = [t.pcd1 for at, t in b.requests() if at > lost_at]
    assert words[0] == IGNORED  # learn its state first, as at start
    assert set(words[1:]) == {STOP_WORD}
    assert not b.drives[1].running


async def test_port_that_will_not_open_is_retried_with_growing_jittered_backoff() -> None:
    b = bench(A, seed=3)
    b.transport.fail_open = True
    async with b.master:
        assert not b.master.is_up
        result = await b.complete(b.submit(orders(b.master, "a").stop()))
        await b.clock.run_until(T0 + 40.0)
        b.transport.fail_open = False
        await b.clock.run_for(60.0)
        assert b.master.is_up
    assert result.outcome is Outcome.CANCELLED
    assert result.reason == "line1 is down: scripted open failure"
    rng = random.Random(3)
    expected, at = [T0], T0
    for attempt in range(20):
        at += min(BACKOFF_MAX_S, BACKOFF_FIRST_S * 2**attempt) * (0.8 + 0.4 * rng.random())
        expected.append(at)
        if at > T0 + 40.0:
            break
    assert b.transport.open_attempts == [approx(t) for t in expected]
    assert b.transport.sent[0].at == approx(expected[-1])


# -- broadcasts --------------------------------------------------------------------------


async def test_broadcast_goes_to_address_0_and_the_line_waits_no_reply() -> None:
    b = bench(A, B, fc=[FcDrive(1, running=True, output_pct=30.0), FcDrive(2)])
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        await b.mid_transaction()
        count = len(b.transport.sent)
        result = await b.complete(b.submit(b.master.execute(None, Command(action=Action.STOP))))
        await b.clock.run_for(0.2)
    assert result.outcome is Outcome.DONE
    broadcast, after = b.transport.sent[count], b.transport.sent[count + 1]
    telegram = b.requests()[count][1]
    assert (broadcast.data[2], telegram.address, telegram.pcd1) == (0x80, 0, STOP_WORD)
    assert broadcast.reply_at is None
    assert after.at == approx(broadcast.at + PROCESS * CHAR_S + 0.010 + PAUSE_S)
    assert b.master.stats.broadcasts == 1
    assert b.master.stats.timeouts == 0
    assert {t.pcd1 for _, t in b.requests()[count + 1 :]} == {STOP_WORD}
    assert not b.drives[1].running


async def test_broadcast_is_refused_when_any_drive_is_monitor_only() -> None:
    b = bench(A, M)
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        result = await b.complete(
            b.submit(b.master.execute(None, Command(action=Action.START, reference_pct=10.0)))
        )
        await b.clock.run_for(0.1)
    assert result.outcome is Outcome.NOT_ALLOWED
    assert "m is monitor-only" in result.reason
    assert 0 not in {t.address for _, t in b.requests()}


# -- demotion, probing, recovery ---------------------------------------------------------


async def test_silent_drive_is_demoted_then_probed_only_at_the_probe_interval() -> None:
    b = bench(A, M, fc=[FcDrive(1), FcDrive(3)], probe_interval_s=1.0)
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        b.drives[3].silent = True  # it answered, then fell silent
        await b.clock.run_until(T0 + 6.0)
    to_m = [(at, t) for at, t in b.requests(3) if at > last_reply_at(b, "m")]
    polls, probes = to_m[:3], to_m[3:]
    assert {len((t.pke and b"x" * PARAMETER) or b"x" * PROCESS) for _, t in polls} == {PARAMETER}
    ((name, online, demoted_at),) = b.observer.availability[2:]
    assert (name, online) == ("m", False)
    assert len(probes) == 5
    assert all(t.pke is None and (t.pcd1, t.pcd2) == (IGNORED, 0) for _, t in probes)
    times = [demoted_at] + [at for at, _ in probes]
    longest = b.plan.reply_timeout(PARAMETER, PARAMETER) + b.plan.wire_s(PARAMETER) + 0.003
    for before, after in itertools.pairwise(times):
        assert 1.0 <= after - before <= 1.0 + longest


async def test_demoted_drive_comes_back_when_a_probe_is_answered() -> None:
    b = bench(A, M, fc=[FcDrive(1), FcDrive(3, silent=True)], probe_interval_s=1.0)
    async with b.master:
        await b.clock.run_until(T0 + 1.5)
        b.drives[3].silent = False
        await b.clock.run_until(T0 + 3.0)
    names = [(name, online) for name, online, _ in b.observer.availability]
    assert names == [("a", True), ("m", False), ("m", True)]
    back_at = b.observer.availability[-1][2]
    after = [t.address for at, t in b.requests() if at > back_at]
    assert after[:6] in ([1, 3] * 3, [3, 1] * 3)


async def test_running_drive_that_returns_after_demotion_is_adopted_again() -> None:
    b = bench(A, fc=[FcDrive(1, running=True, output_pct=50.0)], probe_interval_s=0.5)
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        b.drives[1].silent = True
        await b.clock.run_until(T0 + 1.0)
        b.drives[1].silent = False
        b.drives[1].running, b.drives[1].output_pct = False, 0.0  # stopped while away
        back = b.clock.now()
        await b.clock.run_until(T0 + 2.0)
    probes = [t for at, t in b.requests() if at > T0 + 0.3 and t.pke is None]
    assert probes
    assert {t.pcd1 for t in probes} == {IGNORED}
    words = [t.pcd1 for at, t in b.requests() if at > back]
    assert words[0] == IGNORED
    assert set(words[1:]) == {STOP_WORD}
    assert not b.drives[1].running


async def test_drive_that_was_told_to_stop_is_probed_with_the_stop_word() -> None:
    b = bench(A, fc=[FcDrive(1, running=True, output_pct=50.0)], probe_interval_s=0.5)
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
        await b.complete(b.submit(orders(b.master, "a").stop()))
        b.drives[1].silent = True
        await b.clock.run_until(T0 + 2.0)
    probes = [t for at, t in b.requests() if at > T0 + 0.3 and t.pke is None]
    assert len(probes) >= 2
    assert {t.pcd1 for t in probes} == {STOP_WORD}


# -- shutdown: exactly one outcome per command -------------------------------------------


async def test_every_command_gets_exactly_one_outcome_also_at_shutdown() -> None:
    b = bench(A, B, fc=[FcDrive(1, silent=True), FcDrive(2)])
    async with b.master:
        await b.clock.run_until(T0 + 0.5)
        calls = [
            orders(b.master, "a").start(reference_pct=10.0),
            orders(b.master, "b").read("16-13"),
            orders(b.master, "a").read("16-13"),
            orders(b.master, "b").start(reference_pct=20.0),
            orders(b.master, "a").set_reference(reference_pct=30.0),
            orders(b.master, "b").stop(),
            orders(b.master, "a").stop(),
        ]
        tasks = [b.submit(call) for call in calls]
        await b.clock.run_for(0.15)
        assert any(task.done() for task in tasks)
        assert not all(task.done() for task in tasks)
    for task in tasks:
        await task
    outcomes = [task.result().outcome for task in tasks]
    assert Outcome.CANCELLED in outcomes
    assert {o for o in outcomes} <= {
        Outcome.DONE,
        Outcome.TIMEOUT,
        Outcome.CANCELLED,
        Outcome.SUPERSEDED,
    }
    reported = [id(command) for _, command, _ in b.observer.results]
    assert len(reported) == len(tasks) == len(set(reported))
    reasons = {r.reason for r in (t.result() for t in tasks) if r.outcome is Outcome.CANCELLED}
    assert "line1 shut down" in reasons
    assert reasons <= {"line1 shut down", "superseded by stop"}
    assert b.transport.closed == 1


async def test_command_after_shutdown_is_cancelled_at_once() -> None:
    b = bench(A)
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
    assert not b.master.is_up
    result = await orders(b.master, "a").stop()
    assert result.outcome is Outcome.CANCELLED


async def test_command_sent_right_after_entering_finds_the_line_open() -> None:
    b = bench(A)
    async with b.master:
        assert b.master.is_up
        result = await b.complete(b.submit(orders(b.master, "a").stop()))
    assert result.outcome is Outcome.DONE
    assert b.words(1)[:2] == [IGNORED, STOP_WORD]


async def test_master_is_not_reentrant() -> None:
    b = bench(A)
    async with b.master:
        with pytest.raises(RuntimeError, match="not re-entrant"):
            await b.master.__aenter__()


async def test_status_word_bits_reach_the_observer_unchanged() -> None:
    b = bench(A, fc=[FcDrive(1, warning=True)])
    async with b.master:
        await b.clock.run_until(T0 + 0.1)
    status = b.observer.replies[0][1].status
    assert status is not None
    assert status.word == b.drives[1].status_word
    assert status.warning
    assert status.word & StatusWord.BUS_CONTROL
    assert b.observer.replies[0][3] == ControlIntent(Motion.STOP)  # adopted from this reply


# -- no pulses: a command that timed out is never undone -----------------------------------


async def test_a_start_applied_with_its_replies_lost_is_adopted_never_stopped() -> None:
    drive = FcDrive(1)
    line = FcLine(drive)

    def lose_start_replies(request: bytes) -> bytes | Timed | None:
        reply = line(request)  # the drive acts on every request
        if drive.received[-1].pcd1 & ControlWord.START and drive.received[-1].pke is None:
            starts = [t for t in drive.received if t.pcd1 & ControlWord.START]
            if len(starts) <= 2:  # the start and its retry: applied, unanswered
                return None
        return reply

    b = bench(A, fc=[drive], responder=lose_start_replies, offline_after=99)
    async with b.master:
        await b.clock.run_until(T0 + 0.2)
        assert b.words(1)[-1] == STOP_WORD  # adopted stopped
        result = await b.complete(b.submit(orders(b.master, "a").start(reference_pct=50.0)))
        assert result.outcome is Outcome.TIMEOUT
        sent_before = len(b.words(1))
        await b.clock.run_for(0.5)
    after = b.words(1)[sent_before:]
    assert after, "the drive was polled after the timeout"
    assert not [w for w in after if w & ControlWord.DATA_VALID and not w & ControlWord.START]
    assert after[0] & ControlWord.DATA_VALID == 0  # the first poll commands nothing
    assert after[-1] == RUN_WORD  # then what the drive shows: running at 50 %
    assert {t.pcd2 for _, t in b.requests(1)[-3:]} == {encode_reference(50.0)}
    assert drive.running
    assert drive.output_pct == pytest.approx(50.0, abs=0.01)


async def test_what_the_config_forbids_is_refused_as_such_while_the_line_is_down() -> None:
    # A monitor-only drive's start is not allowed, up or down: "cancelled, the line is
    # down" would say it might work once the line is back.
    b = bench(A, M)
    b.transport.fail_open = True
    async with b.master:
        assert not b.master.is_up
        start = await b.complete(b.submit(orders(b.master, "m").start(frequency_hz=20.0)))
        stop = await b.complete(b.submit(orders(b.master, "a").stop()))
    assert start.outcome is Outcome.NOT_ALLOWED
    assert start.reason == "m is monitor-only (not configured control: bus)"
    assert stop.outcome is Outcome.CANCELLED
    assert stop.reason == "line1 is down: scripted open failure"
