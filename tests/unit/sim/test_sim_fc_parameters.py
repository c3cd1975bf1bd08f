"""The simulated FC drive's parameter channel: values, widths, writes and AK 7 refusals."""

from __future__ import annotations

import pytest

from fcmaster.errors import UsageError
from fcmaster.protocol.codec import Access
from fcmaster.protocol.danfoss_fc import (
    PARAMETERS,
    ResponseAk,
    Telegram,
    decode_telegram,
    make_pke,
)
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.danfoss_fc.error_codes import (
    BAD_INDEX,
    ILLEGAL_PARAMETER,
    LIMIT_EXCEEDED,
    NO_TEXT,
    NOT_AN_ARRAY,
    NOT_WHILE_RUNNING,
    READ_ONLY,
    REQUEST_NOT_SUPPORTED,
    WRONG_DATA_TYPE,
)
from fcmaster.protocol.drive import ControlIntent, Motion
from fcmaster.sim import DriveSettings, LineSettings, build_line
from tests.fakes import FakeClock
from tests.unit.sim.wire import REF_100, START, ask, control, drive, fc_line, read, transact, write


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


def test_every_parameter_in_the_codec_table_reads_back_through_the_codec(
    clock: FakeClock,
) -> None:
    line = fc_line(clock, (1,))
    codec = FcCodec()
    ask(line, clock, control(1, START, REF_100))
    clock.time += 10.0
    values = {}
    for _pnu, spec in PARAMETERS.items():
        (exchange,) = codec.read(1, codec.parameter(spec.number), 0, None)
        reply = codec.parse(exchange, transact(line, clock, exchange.request))
        assert reply.error is None, spec.number
        assert reply.value is not None
        values[spec.number] = reply.value.value
    assert values["16-13"] == 50.0
    assert values["16-12"] == 400.0
    assert values["16-14"] == pytest.approx(8.2, abs=0.1)  # 0.7 load on an 11 A motor
    assert values["16-10"] == pytest.approx(4.05, abs=0.01)
    assert values["16-17"] == pytest.approx(1465, abs=2)
    assert values["16-30"] == pytest.approx(547, abs=2)
    assert values["16-05"] == 100.0
    assert values["3-41"] == 3.0
    assert values["8-31"] == 1
    assert values["15-40"] == "FC-302"
    assert values["16-03"] == 0x0F07


def test_reads_answer_ak_1_for_16_bit_and_ak_2_for_32_bit(clock: FakeClock) -> None:
    line = fc_line(clock, (1,))
    assert ask(line, clock, read(1, 1613)).ak == ResponseAk.VALUE_WORD
    reply = ask(line, clock, read(1, 341))
    assert (reply.ak, reply.pnu, reply.pwe) == (ResponseAk.VALUE_DWORD, 341, 300)


def test_write_is_echoed_and_takes_effect(clock: FakeClock) -> None:
    line = fc_line(clock, (1,))
    codec = FcCodec()
    (exchange,) = codec.write(1, codec.parameter("3-41"), 0, 1.0, None)
    reply = codec.parse(exchange, transact(line, clock, exchange.request))
    assert reply.value is not None
    assert reply.value.value == 1.0
    assert exchange.access is Access.WRITE
    ask(line, clock, control(1, START, REF_100))
    clock.time += 0.5
    drive(line, 1).advance(clock.now())
    assert drive(line, 1).motor.frequency_hz == pytest.approx(25.0, abs=1.0)


def test_vendor_example_write_4_14_with_ak_e(clock: FakeClock) -> None:
    line = fc_line(clock, (1,))
    reply = ask(line, clock, write(1, 414, 1000, ak=0xE))  # 100.0 Hz, RAM + EEPROM
    assert (reply.ak, reply.pwe) == (ResponseAk.VALUE_WORD, 1000)


@pytest.mark.parametrize(
    ("request_", "code"),
    [
        (read(1, 999), ILLEGAL_PARAMETER),
        (write(1, 999, 1), ILLEGAL_PARAMETER),
        (write(1, 1613, 0), READ_ONLY),
        (write(1, 341, 0, ak=0x3), LIMIT_EXCEEDED),
        (write(1, 341, 400_000, ak=0x3), LIMIT_EXCEEDED),
        (write(1, 804, 6), LIMIT_EXCEEDED),  # not an option
        (write(1, 412, 700), LIMIT_EXCEEDED),  # above 4-14
        (write(1, 414, 0x1_0000, ak=0x3), LIMIT_EXCEEDED),  # a double word beyond 16 bits
        (write(1, 341, 500, ak=0x2), WRONG_DATA_TYPE),  # a word write to a 32-bit parameter
        (read(1, 1613, ind=1), NOT_AN_ARRAY),
        (read(1, 1530, ind=10), BAD_INDEX),
        (Telegram(address=1, pke=make_pke(0xF, 1613), ind=0x0400), NO_TEXT),
        (Telegram(address=1, pke=make_pke(0xF, 1540), ind=0x0500, text=b"X"), READ_ONLY),
        (Telegram(address=1, pke=make_pke(0x4, 341), ind=1), REQUEST_NOT_SUPPORTED),
        (Telegram(address=1, pke=make_pke(0x9, 341)), REQUEST_NOT_SUPPORTED),
    ],
    ids=lambda value: "" if isinstance(value, Telegram) else str(value),
)
def test_refusals_answer_ak_7_with_the_error_code(
    clock: FakeClock, request_: Telegram, code: int
) -> None:
    line = fc_line(clock, (1,))
    reply = ask(line, clock, request_)
    assert reply.ak == ResponseAk.ERROR
    assert reply.pwe & 0xFFFF == code
    assert reply.pnu == request_.pnu


def test_motor_data_cannot_change_while_running(clock: FakeClock) -> None:
    line = fc_line(clock, (1,))
    assert ask(line, clock, write(1, 122, 230)).ak == ResponseAk.VALUE_WORD  # stopped: fine
    ask(line, clock, control(1, START, REF_100))
    reply = ask(line, clock, write(1, 122, 400))
    assert (reply.ak, reply.pwe) == (ResponseAk.ERROR, NOT_WHILE_RUNNING)
    clock.time += 10.0
    drive(line, 1).advance(clock.now())
    assert drive(line, 1).motor.voltage_v == pytest.approx(230.0)


def test_text_parameters_come_back_in_a_text_block(clock: FakeClock) -> None:
    line = fc_line(clock, (1, 2))
    request = Telegram(address=2, pke=make_pke(0xF, 1551), ind=0x0400)
    reply = ask(line, clock, request)
    assert (reply.ak, reply.text) == (0xF, b"002123G456")


def test_alarm_log_and_counters(clock: FakeClock) -> None:
    line = fc_line(clock, (1,))
    ask(line, clock, control(1, START, REF_100))
    clock.time += 7200.0
    assert ask(line, clock, read(1, 1500)).pwe == 2
    assert ask(line, clock, read(1, 1501)).pwe == 2
    assert ask(line, clock, read(1, 1502)).pwe == 8  # 4.05 kW for two hours
    drive(line, 1).control.raise_alarm(13, clock.now())
    assert ask(line, clock, read(1, 1530, ind=0)).pwe == 13
    assert ask(line, clock, read(1, 1532, ind=0)).pwe == pytest.approx(7200, abs=1)
    assert ask(line, clock, read(1, 1530, ind=1)).pwe == 0
    assert ask(line, clock, read(1, 1690)).pwe == 1 << 5


def test_broadcast_writes_reach_every_drive(clock: FakeClock) -> None:
    line = fc_line(clock, (1, 2, 3))
    assert transact(line, clock, write(0, 804, 2)) == b""
    assert all(drive(line, a).parameters[804] == 2 for a in (1, 2, 3))


def test_a_new_address_takes_effect_after_the_reply(clock: FakeClock) -> None:
    line = fc_line(clock, (1,))
    assert ask(line, clock, write(1, 831, 7)).address == 1
    assert transact(line, clock, read(1, 1613)) == b""
    assert ask(line, clock, read(7, 1613)).address == 7


def test_8_35_sets_the_response_delay(clock: FakeClock) -> None:
    line = fc_line(clock, (1,))
    ask(line, clock, write(1, 835, 40))
    written = clock.now()
    transact(line, clock, control(1, 0))
    assert clock.now() - written == pytest.approx(line.wire_s(16) + 0.040)


def test_settings_and_line_format_set_the_port_parameters(clock: FakeClock) -> None:
    line = build_line(
        LineSettings(baudrate=115200, parity="N", stopbits=2),
        [(5, DriveSettings(response_delay_s=0.02, parameters={"3-41": 1.5}))],
        clock=clock,
    )
    store = drive(line, 5).parameters
    assert (store[831], store[832], store[833], store[835], store[341]) == (5, 7, 3, 20, 150)


@pytest.mark.parametrize(
    "parameters",
    [{"16-13": 1.0}, {"3-41": 0.0}, {"4-12": 70.0}, {"8-04": 6}, {"nonsense": 1}],
)
def test_bad_parameter_settings_are_refused(parameters: dict[str, float]) -> None:
    with pytest.raises(UsageError):
        build_line(LineSettings(), [(1, DriveSettings(parameters=parameters))], clock=FakeClock())


def test_settings_may_raise_a_bound_and_a_value_together() -> None:
    line = build_line(
        LineSettings(),
        [(1, DriveSettings(parameters={"3-19": 80.0, "4-14": 100.0}))],
        clock=FakeClock(),
    )
    assert drive(line, 1).parameters.value(319) == 80.0


def test_codec_control_intents_drive_the_simulated_drive(clock: FakeClock) -> None:
    line = fc_line(clock, (1,))
    codec = FcCodec()
    (run,) = codec.control(1, ControlIntent(Motion.RUN, reference_pct=50.0))
    transact(line, clock, run.request)
    clock.time += 5.0
    (stop,) = codec.control(1, ControlIntent(Motion.QUICK_STOP))
    reply = codec.parse(stop, transact(line, clock, stop.request))
    assert reply.status is not None
    assert reply.status.running
    assert reply.output_frequency_hz == pytest.approx(25.0, abs=0.5)  # 50 % of 50 Hz
    clock.time += 5.0
    reply = codec.parse(stop, transact(line, clock, stop.request))
    assert reply.status is not None
    assert not reply.status.running
    assert decode_telegram(stop.request, from_drive=False).pcd1 & 0x0400
