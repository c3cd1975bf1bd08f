"""MitsubishiCodec through the DriveCodec seam: polls, control, access, parse.

Expected frames are spelled out by hand with their sums in the comments (ASCII "0"=48
"1"=49 "2"=50 "3"=51 "4"=52 "5"=53 "6"=54 "7"=55 "8"=56 "9"=57 "A"=65 "B"=66 "C"=67 "D"=68
"E"=69 "F"=70). The codec sends the waiting-time digit "0" unless told another waiting
time, or none when the drives' Pr.123 sets it (``wait_time_ms=None``).
"""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.errors import MalformedReply, ProtocolError, UnexpectedReply, UsageError
from fcmaster.protocol.codec import Access, Condition, ConditionReport, DriveCodec, DriveError
from fcmaster.protocol.drive import ControlIntent, Motion
from fcmaster.protocol.mitsubishi import (
    RESTART_S,
    MitsubishiCodec,
    Request,
    answer_delay_s,
    decode_frame,
)

# replies, sums by hand
STATUS_FAULT = b"\x020180\x03C9\r"  # 48+49+56+48 = 201 = 0xC9
STATUS_RUN_FWD_SU = b"\x02010B\x03D3\r"  # 48+49+48+66 = 211 = 0xD3
STATUS_REVERSE = b"\x020105\x03C6\r"  # 48+49+48+53 = 198 = 0xC6
STATUS_STOPPED = b"\x020100\x03C1\r"  # 48+49+48+48 = 193 = 0xC1
FREQ_50HZ = b"\x02011388\x0335\r"  # 48+49+49+51+56+56 = 309 = 0x135
FAULTS_THT_OPT = b"\x020130A0\x0335\r"  # §9 manual example; 48+49+51+48+65+48 = 309
PR_9999 = b"\x0201FFFF\x0379\r"  # 48+49+4*70 = 377 = 0x179
ACK_1 = b"\x0601\r"
ACK_3 = b"\x0603\r"


@pytest.fixture
def codec() -> MitsubishiCodec:
    return MitsubishiCodec()


def test_codec_meets_the_seam() -> None:
    codec: DriveCodec = MitsubishiCodec(terminator="crlf", wait_time_ms=0, nominal_hz={1: 60.0})
    assert codec.protocol == "mitsubishi"
    assert codec.addresses == range(32)  # station 0 is a drive: the link has no broadcast
    assert codec.min_pause_s(0.0001) == pytest.approx(0.010)


@pytest.mark.parametrize(
    "kwargs",
    [{"terminator": "lf"}, {"wait_time_ms": 5}, {"wait_time_ms": 160}, {"wait_time_ms": -10}],
)
def test_bad_line_settings_are_refused(kwargs: dict[str, object]) -> None:
    with pytest.raises(UsageError):
        MitsubishiCodec(**kwargs)  # type: ignore[arg-type]  # the values' types vary


# ---------------------------------------------------------------- naming


@pytest.mark.parametrize(
    ("text", "name"),
    [
        ("Pr.7", "Pr.7"),
        ("pr7", "Pr.7"),
        ("P 7", "Pr.7"),
        ("7", "Pr.7"),
        ("Pr.122", "Pr.122"),
        ("70", "Pr.70"),  # digits only: a parameter number
        ("H70", "H70"),
        ("H7A", "H7A"),
        ("7a", "H7A"),
        ("0x7A", "H7A"),
        ("h6f", "H6F"),
        ("HED", "H6D"),  # the write code names the same item as its read code
        ("HFA", "HFA"),
    ],
)
def test_parameter_names_are_normalised(codec: MitsubishiCodec, text: str, name: str) -> None:
    assert codec.parameter(text).name == name


@pytest.mark.parametrize("text", ["H07", "C2", "Pr.900", "Pr.1000", "HZZ", "H78", "", "Pr.x"])
def test_unknown_or_paged_names_are_refused(codec: MitsubishiCodec, text: str) -> None:
    with pytest.raises(UsageError):
        codec.parameter(text)


# ---------------------------------------------------------------- polls


def test_status_poll_is_a_read_of_7A(codec: MitsubishiCodec) -> None:
    # 48+49+55+65+48 = 265 = 0x109 -> "09"
    exchange = codec.poll(1, None, None)
    assert exchange.request == b"\x05017A009\r"
    assert exchange.reply_length == len(STATUS_STOPPED)
    assert exchange.access is Access.NONE
    assert not exchange.carries_control


def test_status_poll_without_waiting_digit_or_terminator() -> None:
    # 48+49+55+65 = 217 = 0xD9
    codec = MitsubishiCodec(terminator="none", wait_time_ms=None)
    assert codec.poll(1, None, None).request == b"\x05017AD9"


def test_the_waiting_time_travels_as_its_digit() -> None:
    # 50 ms is digit "5": 48+49+55+65+53 = 270 = 0x10E
    codec = MitsubishiCodec(wait_time_ms=50)
    assert codec.poll(1, None, None).request == b"\x05017A50E\r"
    assert MitsubishiCodec(wait_time_ms=150).poll(1, None, None).request[5:6] == b"F"


def test_answer_delay_covers_the_waiting_time_and_parameter_access() -> None:
    assert answer_delay_s(0) == pytest.approx(0.030)
    assert answer_delay_s(100) == pytest.approx(0.130)
    assert answer_delay_s(None) == pytest.approx(0.180)  # Pr.123 unknown: at worst 150 ms


def test_reset_gets_no_reply_and_leaves_the_drive_deaf(codec: MitsubishiCodec) -> None:
    # FD 9696: 48+49+70+68+48+57+54+57+54 = 505 = 0x1F9
    (reset,) = codec.control(1, ControlIntent(Motion.RUN, reference_pct=50.0, reset=True))
    assert reset.request == b"\x0501FD09696F9\r"
    assert not reset.expects_reply
    assert reset.deaf_s == pytest.approx(RESTART_S)
    assert all(e.deaf_s == 0.0 for e in codec.control(1, ControlIntent(Motion.RUN)))


@pytest.mark.parametrize("motion", list(Motion))
def test_polls_never_command(codec: MitsubishiCodec, motion: Motion) -> None:
    intent = ControlIntent(motion, reference_pct=50.0)
    for read in (None, *codec.default_monitor()):
        exchange = codec.poll(1, intent, read)
        request = decode_frame(exchange.request)
        assert isinstance(request, Request)
        assert request.is_read
        assert not exchange.carries_control


def test_poll_sequence_puts_the_status_before_every_monitored_item(
    codec: MitsubishiCodec,
) -> None:
    h6f, h70 = codec.parameter("H6F"), codec.parameter("H70")
    assert codec.poll_sequence((h6f, h70)) == (None, h6f, None, h70)
    assert codec.poll_sequence(()) == (None,)
    assert codec.default_monitor() == tuple(codec.parameter(p) for p in ("H6F", "H70", "H71"))


@pytest.mark.parametrize("name", ["Pr.7", "HFA"])
def test_poll_sequence_refuses_what_one_read_cannot_poll(codec: MitsubishiCodec, name: str) -> None:
    with pytest.raises(UsageError):
        codec.poll_sequence((codec.parameter(name),))


def test_condition_parameters_read_the_fault_history(codec: MitsubishiCodec) -> None:
    assert codec.condition_parameters(alarms=True, warnings=True) == (codec.parameter("H74"),)
    assert codec.condition_parameters(alarms=False, warnings=True) == ()


# ---------------------------------------------------------------- control


def test_run_writes_the_frequency_then_the_run_command(codec: MitsubishiCodec) -> None:
    # 100 % of 50 Hz = 5000 = 0x1388: 48+51+69+68+48+49+51+56+56 = 496 = 0x1F0
    # FA 02: 48+51+70+65+48+48+50 = 380 = 0x17C
    frequency, command = codec.control(3, ControlIntent(Motion.RUN, reference_pct=100.0))
    assert frequency.request == b"\x0503ED01388F0\r"
    assert command.request == b"\x0503FA0027C\r"
    assert frequency.carries_control
    assert command.carries_control
    assert command.reply_length == len(b"\x1503A\r")  # room for a NAK


def test_run_uses_the_drives_nominal_frequency() -> None:
    # 50 % of 60 Hz = 3000 = 0x0BB8: 48+50+69+68+48+48+66+66+56 = 519 = 0x207 -> "07"
    codec = MitsubishiCodec(nominal_hz={2: 60.0})
    frequency, _ = codec.control(2, ControlIntent(Motion.RUN, reference_pct=50.0))
    assert frequency.request == b"\x0502ED00BB807\r"


@pytest.mark.parametrize(
    ("intent", "wire"),
    [
        # FA 04: 48+51+70+65+48+48+52 = 382 = 0x17E
        (ControlIntent(Motion.RUN, reverse=True, reference_pct=10.0), b"\x0503FA0047E\r"),
        # FA 00: 378 = 0x17A
        (ControlIntent(Motion.STOP, reverse=True), b"\x0503FA0007A\r"),
        (ControlIntent(Motion.QUICK_STOP), b"\x0503FA0007A\r"),
        # FA 80 (MRS): 48+51+70+65+48+56+48 = 386 = 0x182
        (ControlIntent(Motion.COAST), b"\x0503FA08082\r"),
    ],
    ids=["reverse", "stop", "quick-stop", "coast"],
)
def test_run_command_data(codec: MitsubishiCodec, intent: ControlIntent, wire: bytes) -> None:
    assert codec.control(3, intent)[-1].request == wire


def test_stops_send_only_the_run_command(codec: MitsubishiCodec) -> None:
    for motion in (Motion.STOP, Motion.QUICK_STOP, Motion.COAST):
        assert len(codec.control(3, ControlIntent(motion, reference_pct=80.0))) == 1


def test_reset_expects_no_reply(codec: MitsubishiCodec) -> None:
    # FD 9696 with digit "0": 48+49+70+68+48+57+54+57+54 = 505 = 0x1F9
    (exchange,) = codec.control(1, ControlIntent(Motion.RUN, reset=True))
    assert exchange.request == b"\x0501FD09696F9\r"
    assert exchange.reply_length == 0
    assert not exchange.expects_reply


@pytest.mark.parametrize(
    "intent",
    [
        ControlIntent(Motion.JOG),
        ControlIntent(Motion.RUN, reference_pct=-10.0),
        ControlIntent(Motion.RUN, reference_pct=1400.0),  # 700 Hz: beyond four digits
        ControlIntent(Motion.RUN, reference_pct=float("nan")),
    ],
    ids=["jog", "negative", "too-high", "nan"],
)
def test_what_the_link_cannot_carry_is_refused(
    codec: MitsubishiCodec, intent: ControlIntent
) -> None:
    with pytest.raises(UsageError):
        codec.control(1, intent)


# ---------------------------------------------------------------- read / write


def test_read_of_an_item_is_one_exchange(codec: MitsubishiCodec) -> None:
    # 6F read: 48+49+54+70+48 = 269 = 0x10D -> "0D"
    (exchange,) = codec.read(1, codec.parameter("H6F"), 0, None)
    assert exchange.request == b"\x05016F00D\r"
    assert exchange.access is Access.READ
    assert exchange.reply_length == len(FREQ_50HZ)


def test_parameter_read_sets_the_page_first(codec: MitsubishiCodec) -> None:
    # FF 00: 48+49+70+70+48+48+48 = 381 = 0x17D; 07 read: 48+49+48+55+48 = 248 = 0xF8
    page, read = codec.read(1, codec.parameter("Pr.7"), 0, None)
    assert page.request == b"\x0501FF0007D\r"
    assert read.request == b"\x0501070F8\r"
    assert read.reply_length == len(b"\x02010000AA\x0300\r")  # six digits fit
    assert (page.access, read.access) == (Access.NONE, Access.READ)
    with pytest.raises(UsageError):  # a parameter cannot be polled: it needs the page
        codec.poll(1, None, codec.parameter("Pr.7"))


def test_parameter_write_in_its_unit(codec: MitsubishiCodec) -> None:
    # Pr.7 = 5.0 s -> 50 = 0x0032: 48+49+56+55+48+48+48+51+50 = 453 = 0x1C5
    page, write = codec.write(1, codec.parameter("Pr.7"), 0, 5.0, None)
    assert page.request == b"\x0501FF0007D\r"
    assert write.request == b"\x05018700032C5\r"
    # Pr.122 = 9999 (no check) travels as HFFFF, on page 1 (FF 01: 381 + 1 = 0x17E)
    page, write = codec.write(1, codec.parameter("Pr.122"), 0, 9999, None)
    assert page.request == b"\x0501FF0017E\r"
    assert write.request[5:10] == b"0FFFF"


def test_set_frequency_write_goes_to_ram_unless_persisted(codec: MitsubishiCodec) -> None:
    key = codec.parameter("H6D")
    assert codec.write(1, key, 0, 50.0, None)[0].request[3:5] == b"ED"
    # EE 1388: 48+49+69+69+48+49+51+56+56 = 495 = 0x1EF
    (persisted,) = codec.write(1, key, 0, 50.0, None, persist=True)
    assert persisted.request == b"\x0501EE01388EF\r"


@pytest.mark.parametrize(
    ("name", "value", "index"),
    [
        ("HFA", 2, 0),  # the run command goes through control()
        ("HFD", 0x9696, 0),
        ("H6F", 10, 0),  # read-only
        ("H6D", "fast", 0),
        ("H6D", 50.0, 1),  # no index on this link
        ("H6D", 700.0, 0),  # beyond four digits of 0.01 Hz
        ("H73", 256, 0),  # two digits
    ],
)
def test_writes_that_cannot_go_are_refused(
    codec: MitsubishiCodec, name: str, value: float | str, index: int
) -> None:
    with pytest.raises(UsageError):
        codec.write(1, codec.parameter(name), index, value, None)


def test_write_only_items_cannot_be_read(codec: MitsubishiCodec) -> None:
    with pytest.raises(UsageError):
        codec.read(1, codec.parameter("HFA"), 0, None)


# ---------------------------------------------------------------- parse


@pytest.mark.parametrize(
    ("reply", "running", "reverse", "at_reference", "fault"),
    [
        (STATUS_STOPPED, False, None, False, False),
        (STATUS_RUN_FWD_SU, True, False, True, False),
        (STATUS_REVERSE, True, True, False, False),
        (STATUS_FAULT, False, None, False, True),
    ],
    ids=["stopped", "forward-at-frequency", "reverse", "fault"],
)
def test_status_reply_is_normalised(
    codec: MitsubishiCodec,
    reply: bytes,
    running: bool,
    reverse: bool | None,
    at_reference: bool,
    fault: bool,
) -> None:
    result = codec.parse(codec.poll(1, None, None), reply)
    assert result.status is not None
    assert result.status.word == int(reply[3:5], 16)
    assert (result.status.running, result.status.reverse) == (running, reverse)
    assert (result.status.at_reference, result.status.fault) == (at_reference, fault)
    assert result.output_frequency_hz is None  # H7A does not carry it


def test_output_frequency_reply(codec: MitsubishiCodec) -> None:
    result = codec.parse(codec.read(1, codec.parameter("H6F"), 0, None)[0], FREQ_50HZ)
    assert result.output_frequency_hz == pytest.approx(50.0)
    assert result.value is not None
    assert (result.value.raw, result.value.value, result.value.unit) == (5000, 50.0, "Hz")


def test_fault_history_is_an_alarm_only_while_the_status_shows_a_fault(
    codec: MitsubishiCodec,
) -> None:
    (history,) = codec.read(1, codec.parameter("H74"), 0, None)
    assert codec.parse(history, FAULTS_THT_OPT).conditions is None  # status not known yet
    assert codec.parse(codec.poll(1, None, None), STATUS_FAULT).conditions is None
    result = codec.parse(history, FAULTS_THT_OPT)
    assert result.conditions == ConditionReport(
        kind="alarm", source="H74", active=(Condition(0xA0, "E.OPT option fault"),)
    )
    assert result.value is not None
    assert result.value.value == "E.OPT option fault; E.THT inverter overload (transistor thermal)"
    cleared = codec.parse(codec.poll(1, None, None), STATUS_STOPPED)
    assert cleared.conditions == ConditionReport(kind="alarm", source="H74", active=())
    assert codec.parse(history, FAULTS_THT_OPT).conditions == cleared.conditions


def test_nak_is_the_drives_refusal(codec: MitsubishiCodec) -> None:
    (command,) = codec.control(3, ControlIntent(Motion.STOP))
    result = codec.parse(command, b"\x1503A\r")
    assert result.error is not None
    assert result.error == DriveError(0xA, result.error.text)
    assert result.error.text.startswith("Mode error")


def test_ack_confirms_a_write_with_its_value(codec: MitsubishiCodec) -> None:
    (exchange,) = codec.write(3, codec.parameter("H6D"), 0, 42.5, None)
    result = codec.parse(exchange, ACK_3)
    assert result.error is None
    assert result.value is not None
    assert (result.value.value, result.value.raw, result.value.unit) == (42.5, 4250, "Hz")
    assert codec.parse(codec.control(3, ControlIntent())[0], ACK_3).value is None


def test_parameter_read_reply_with_the_9999_setting(codec: MitsubishiCodec) -> None:
    _, read = codec.read(1, codec.parameter("Pr.122"), 0, None)
    value = codec.parse(read, PR_9999).value
    assert value is not None
    assert (value.value, value.raw, value.unit) == (9999.0, 0xFFFF, "s")


@pytest.mark.parametrize(
    ("make", "reply"),
    [
        ("status", b"\x020280\x03CA\r"),  # station 2 answering station 1: 48+50+56+48 = 202
        ("status", ACK_1),  # an ACK to a read
        ("status", FREQ_50HZ),  # four digits to H7A, which has two
        ("stop", STATUS_STOPPED),  # data to a write
        ("status", b"\x1501\r"),  # a NAK without code is a master's
        ("status", b"\x05017A009\r"),  # our own request heard back
    ],
)
def test_replies_that_do_not_answer_are_unexpected(
    codec: MitsubishiCodec, make: str, reply: bytes
) -> None:
    exchange = (
        codec.poll(1, None, None) if make == "status" else codec.control(1, ControlIntent())[0]
    )
    with pytest.raises(UnexpectedReply):
        codec.parse(exchange, reply)


def test_a_wrong_sum_is_malformed(codec: MitsubishiCodec) -> None:
    with pytest.raises(MalformedReply):
        codec.parse(codec.poll(1, None, None), b"\x020100\x03C2\r")


exchange_makers = st.sampled_from(["status", "H6F", "H74", "H7C", "Pr.7", "stop", "H6D"])


@given(exchange_makers, st.binary(max_size=30) | st.sampled_from([STATUS_STOPPED, ACK_1]))
def test_parse_raises_only_protocol_errors(make: str, frame: bytes) -> None:
    codec = MitsubishiCodec()
    if make == "status":
        exchange = codec.poll(1, None, None)
    elif make == "stop":
        exchange = codec.control(1, ControlIntent())[0]
    elif make == "H6D":
        exchange = codec.write(1, codec.parameter(make), 0, 1.0, None)[-1]
    else:
        exchange = codec.read(1, codec.parameter(make), 0, None)[-1]
    with contextlib.suppress(ProtocolError):
        codec.parse(exchange, frame)
