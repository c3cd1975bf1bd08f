"""The Modbus RTU codec behind the bus's seam: the bytes each poll and command puts on the
wire for each profile, and what each answer means."""

from __future__ import annotations

import dataclasses

import pytest

from fcmaster.errors import UnexpectedReply, UsageError
from fcmaster.protocol.codec import Exchange
from fcmaster.protocol.drive import ControlIntent, Motion
from fcmaster.protocol.modbus_rtu import (
    ExceptionReply,
    Function,
    ReadRequest,
    Registers,
    WriteSingle,
    decode_request,
    encode_response,
)
from fcmaster.protocol.modbus_rtu.codec import ModbusCodec
from fcmaster.protocol.modbus_rtu.keys import CONTROL_FEED, FAULT_CODE, OUTPUT_FREQUENCY
from fcmaster.protocol.modbus_rtu.profile import Pacing
from fcmaster.protocol.modbus_rtu.profiles import BUILT_IN
from fcmaster.protocol.registry import spec_for
from fcmaster.subcommands.commission import LineOptions

ABB, V20, ATV, YASKAWA, DANFOSS = 1, 2, 3, 4, 5
CODEC = ModbusCodec(
    {
        ABB: BUILT_IN["abb-drives"],
        V20: BUILT_IN["sinamics-v20"],
        ATV: BUILT_IN["altivar-cia402"],
        YASKAWA: BUILT_IN["yaskawa-memobus"],
        DANFOSS: BUILT_IN["danfoss-fc-modbus"],
    },
    {a: 50.0 for a in range(1, 6)},
)
STOP = ControlIntent(Motion.STOP)


def writes(exchanges: tuple[Exchange, ...]) -> list[tuple[int, int]]:
    """(register, value) of each single-register write, in order."""
    out = []
    for exchange in exchanges:
        request = decode_request(exchange.request)
        assert isinstance(request, WriteSingle)
        out.append((request.register, request.value))
    return out


def fresh() -> ModbusCodec:
    return ModbusCodec(CODEC.profiles, CODEC.nominal_hz)


# ---------------------------------------------------------------- polls


def test_abb_status_and_output_frequency_come_in_one_read() -> None:
    poll = CODEC.poll(ABB, None, None)
    assert poll.request.hex(" ") == "01 03 00 03 00 02 34 0b"  # 400004-400005
    assert poll.reply_length == 9
    answer = encode_response(
        Registers(address=ABB, function=Function.READ_HOLDING, values=(0x0337, 12000))
    )
    reply = CODEC.parse(poll, answer)
    assert reply.status is not None
    assert reply.status.running
    assert reply.status.at_reference
    assert reply.output_frequency_hz == pytest.approx(30.0)  # 12000 / 20000 of 50 Hz


def test_v20_reads_its_frequency_apart_from_the_status() -> None:
    status = decode_request(CODEC.poll(V20, None, None).request)
    frequency = decode_request(CODEC.poll(V20, None, OUTPUT_FREQUENCY).request)
    assert status == ReadRequest(address=V20, function=Function.READ_HOLDING, start=109, count=1)
    assert frequency == ReadRequest(address=V20, function=Function.READ_HOLDING, start=23, count=1)
    poll = CODEC.poll(V20, None, OUTPUT_FREQUENCY)
    answer = encode_response(
        Registers(address=V20, function=Function.READ_HOLDING, values=(0xFC18,))
    )
    reply = CODEC.parse(poll, answer)
    assert reply.status is None
    assert reply.output_frequency_hz == pytest.approx(-10.0)  # signed, 0.01 Hz


def test_a_monitor_only_drive_is_never_written_to() -> None:
    for read in CODEC.poll_sequence(CODEC.default_monitor()):
        request = decode_request(CODEC.poll(ATV, None, read).request)
        assert isinstance(request, ReadRequest)


def test_the_feed_writes_the_steady_word_of_what_the_drive_is_commanded() -> None:
    run = ControlIntent(Motion.RUN, reference_pct=50.0)
    assert writes((CODEC.poll(ATV, run, CONTROL_FEED),)) == [(8501, 0x000F)]
    assert writes((CODEC.poll(ATV, STOP, CONTROL_FEED),)) == [(8501, 0x0007)]
    assert writes((CODEC.poll(ABB, run, CONTROL_FEED),)) == [(0, 0x047F)]
    assert CODEC.poll(ABB, run, CONTROL_FEED).carries_control


def test_each_drive_reads_only_its_own_profiles_values() -> None:
    monitor = CODEC.default_monitor()
    abb_current = CODEC.parameter("hr106")
    assert abb_current in monitor
    # The Altivar has no register 106 of its own: it reads its status instead.
    assert CODEC.poll(ATV, None, abb_current) == CODEC.poll(ATV, None, None)
    assert decode_request(CODEC.poll(ABB, None, abb_current).request) == ReadRequest(
        address=ABB, function=Function.READ_HOLDING, start=106, count=1
    )


def test_a_monitored_value_is_scaled_and_named_by_the_profile() -> None:
    key = CODEC.parameter("hr106")
    poll = CODEC.poll(ABB, None, key)
    answer = encode_response(Registers(address=ABB, function=Function.READ_HOLDING, values=(1234,)))
    value = CODEC.parse(poll, answer).value
    assert value is not None
    assert value.value == pytest.approx(12.34)
    assert (value.unit, value.title) == ("A", "Motor current")


def test_the_fault_register_gives_the_alarm_with_its_text() -> None:
    poll = CODEC.poll(ATV, None, FAULT_CODE)
    assert decode_request(poll.request) == ReadRequest(
        address=ATV, function=Function.READ_HOLDING, start=7121, count=1
    )
    answer = encode_response(Registers(address=ATV, function=Function.READ_HOLDING, values=(9,)))
    conditions = CODEC.parse(poll, answer).conditions
    assert conditions is not None
    assert [(c.code, c.text) for c in conditions.active] == [(9, "OCF Overcurrent")]
    assert CODEC.condition_parameters(alarms=True, warnings=False) == (FAULT_CODE,)


# ---------------------------------------------------------------- commands


def test_a_cia402_start_walks_the_state_machine_after_the_reference() -> None:
    run = ControlIntent(Motion.RUN, reference_pct=60.0)
    assert writes(CODEC.control(ATV, run)) == [(8502, 300), (8501, 6), (8501, 7), (8501, 15)]


def test_control_is_the_same_each_time_it_is_asked() -> None:
    codec = fresh()
    run = ControlIntent(Motion.RUN, reference_pct=60.0)
    assert codec.control(ATV, run) == codec.control(ATV, run)


def test_a_reference_change_while_running_writes_only_the_reference() -> None:
    codec = fresh()
    running = ControlIntent(Motion.RUN, reference_pct=60.0)
    codec.poll(ATV, running, None)  # what the drive is commanded now
    faster = ControlIntent(Motion.RUN, reference_pct=80.0)
    assert writes(codec.control(ATV, faster)) == [(8502, 400)]
    # Reversing is a new start, and a stop is the stop word.
    assert writes(codec.control(ATV, STOP)) == [(8501, 7)]


def test_a_status_read_before_a_start_never_makes_a_reference_change_walk_the_sequence() -> None:
    # The stopped status read before the start, then the start's intent carried by a poll:
    # a reference change before the next status read writes the reference alone (walking
    # the sequence again would pass the running drive through "shutdown").
    codec = fresh()
    status_poll = codec.poll(ATV, STOP, None)
    stopped = Registers(address=ATV, function=Function.READ_HOLDING, values=(0x0231, 0))
    assert codec.parse(status_poll, encode_response(stopped)).status is not None
    codec.poll(ATV, ControlIntent(Motion.RUN, reference_pct=60.0), CONTROL_FEED)
    faster = ControlIntent(Motion.RUN, reference_pct=80.0)
    assert writes(codec.control(ATV, faster)) == [(8502, 400)]
    # Stopped behind the gateway's back while commanded to run: the start walks it again.
    codec.parse(status_poll, encode_response(stopped))
    assert writes(codec.control(ATV, faster)) == [(8502, 400), (8501, 6), (8501, 7), (8501, 15)]


@pytest.mark.parametrize(
    ("address", "intent", "expected"),
    [
        (ABB, ControlIntent(Motion.COAST), [(0, 0x047D)]),
        (ABB, ControlIntent(Motion.QUICK_STOP), [(0, 0x047B)]),
        (ABB, ControlIntent(Motion.STOP, reset=True), [(0, 0x04FE), (0, 0x047E), (0, 0x047E)]),
        (V20, ControlIntent(Motion.RUN, reverse=True, reference_pct=50.0),
         [(100, 0x2000), (99, 0x0C7E), (99, 0x0C7F)]),
        (YASKAWA, ControlIntent(Motion.RUN, reference_pct=50.0), [(2, 2500), (1, 1)]),
        (YASKAWA, ControlIntent(Motion.RUN, reverse=True, reference_pct=50.0),
         [(2, 2500), (1, 2)]),
        (DANFOSS, ControlIntent(Motion.RUN, reference_pct=100.0),
         [(50009, 0x4000), (49999, 0x047C)]),
        (ABB, ControlIntent(Motion.RUN, reverse=True, reference_pct=50.0),
         [(1, 0x10000 - 10000), (0, 0x047E), (0, 0x047F)]),
    ],
)  # fmt: skip
def test_commands_write_the_profiles_words(
    address: int, intent: ControlIntent, expected: list[tuple[int, int]]
) -> None:
    assert writes(fresh().control(address, intent)) == expected


def test_a_command_the_profile_lacks_is_refused() -> None:
    with pytest.raises(UsageError, match="no coast command"):
        CODEC.control(YASKAWA, ControlIntent(Motion.COAST))


def test_a_drive_without_a_profile_is_not_commanded() -> None:
    with pytest.raises(UsageError, match="no profile"):
        CODEC.control(9, STOP)


# ---------------------------------------------------------------- answers


def test_an_exception_is_the_drives_refusal_with_its_text() -> None:
    exchange = CODEC.control(ATV, STOP)[0]
    answer = encode_response(ExceptionReply(address=ATV, function=6, code=4))
    error = CODEC.parse(exchange, answer).error
    assert error is not None
    assert error.code == 4
    assert "failure" in error.text.lower()


def test_a_refused_status_read_is_a_warning_that_its_next_status_clears() -> None:
    # An ABB drive polled through another family's profile refuses the status register.
    codec = fresh()
    poll = codec.poll(ABB, None, None)
    refused = codec.parse(poll, encode_response(ExceptionReply(address=ABB, function=3, code=2)))
    assert refused.status is None
    assert refused.conditions is not None
    assert refused.conditions.kind == "warning"
    (warning,) = refused.conditions.active
    assert warning.code == 2
    assert "refuses the status read of profile abb-drives" in warning.text
    words = (0x0337, 12000)  # status word and ACT1
    answered = encode_response(Registers(address=ABB, function=Function.READ_HOLDING, values=words))
    read = codec.parse(poll, answered)
    assert read.status is not None
    assert read.conditions is not None
    assert (read.conditions.source, read.conditions.active) == (refused.conditions.source, ())
    # A refused write or parameter read is the command's refusal, not a warning of the drive.
    stop = codec.control(ATV, STOP)[0]
    write_refused = encode_response(ExceptionReply(address=ATV, function=6, code=4))
    assert codec.parse(stop, write_refused).conditions is None


def test_a_write_answered_with_another_value_is_not_taken_as_done() -> None:
    exchange = CODEC.control(ATV, STOP)[0]
    wrong = encode_response(WriteSingle(address=ATV, register=8501, value=0x0F))
    with pytest.raises(UnexpectedReply, match="not confirmed"):
        CODEC.parse(exchange, wrong)


def test_an_answer_from_another_drive_is_refused() -> None:
    poll = CODEC.poll(ABB, None, None)
    other = encode_response(Registers(address=2, function=Function.READ_HOLDING, values=(0, 0)))
    with pytest.raises(UnexpectedReply, match="address 2"):
        CODEC.parse(poll, other)


def test_parameters_by_register_read_and_write_in_the_profiles_scaling() -> None:
    key = CODEC.parameter("hr5815")  # ABB 58.16 communication loss time, 0.1 s
    (write,) = CODEC.write(ABB, key, 0, 3.0, None)
    assert decode_request(write.request) == WriteSingle(address=ABB, register=5815, value=30)
    value = CODEC.parse(write, write.request).value
    assert value is not None
    assert value.value == pytest.approx(3.0)
    with pytest.raises(UsageError, match="index"):
        CODEC.read(ABB, key, 1, None)
    with pytest.raises(UsageError, match="not a register"):
        CODEC.parameter("16-13")


def test_the_spec_gives_the_modbus_factory_settings_and_the_t35_pause() -> None:
    spec = spec_for("modbus-rtu")
    assert (spec.factory.baudrate, spec.factory.parity, spec.factory.stopbits) == (19200, "E", 1)
    assert CODEC.min_pause_s(11 / 19200) == pytest.approx(3.5 * 11 / 19200)
    assert CODEC.min_pause_s(11 / 115200) == pytest.approx(0.00175)
    assert spec.codec(None, {}, {ABB: BUILT_IN["abb-drives"]}).protocol == "modbus-rtu"


def test_a_drive_without_a_profile_is_only_looked_for() -> None:
    codec = spec_for("modbus-rtu").codec()  # no profiles, no line profile (a scan)
    poll = codec.poll(12, None, None)
    assert decode_request(poll.request) == ReadRequest(
        address=12, function=Function.READ_HOLDING, start=0, count=1
    )
    refused = encode_response(ExceptionReply(address=12, function=3, code=2))
    assert codec.parse(poll, refused).error is not None  # an answer all the same: it is there
    with pytest.raises(UsageError, match="--profile"):
        codec.control(12, STOP)


def test_the_lines_profile_serves_drives_without_their_own() -> None:
    codec = spec_for("modbus-rtu").codec(
        LineOptions(
            port="p", protocol="modbus-rtu", protocol_options=(("profile", "abb-drives"),)
        ).plan()
    )
    assert writes(codec.control(3, STOP)) == [(0, 0x047E)]


# ---------------------------------------------------------------- pacing


def test_a_parameter_write_carries_the_profiles_wait_after_it() -> None:
    (yaskawa,) = CODEC.write(YASKAWA, CODEC.parameter("hr512"), 0, 20.0, None)
    (abb,) = CODEC.write(ABB, CODEC.parameter("hr512"), 0, 20.0, None)
    assert yaskawa.settle_s == pytest.approx(0.01)  # Yaskawa: after a parameter write
    assert abb.settle_s == 0.0
    # the control word a poll feeds is no parameter write: no wait
    assert CODEC.poll(YASKAWA, STOP, CONTROL_FEED).settle_s == 0.0
    assert all(e.settle_s == 0.0 for e in CODEC.read(YASKAWA, CODEC.parameter("hr512"), 0, None))


def test_the_steps_of_a_sequence_carry_the_wait_between_them_but_not_the_last() -> None:
    profile = dataclasses.replace(
        BUILT_IN["altivar-cia402"], pacing=Pacing(between_steps_s=0.05, after_write_s=0.02)
    )
    codec = ModbusCodec({ATV: profile}, {ATV: 50.0})
    start = codec.control(ATV, ControlIntent(Motion.RUN, reference_pct=50.0))
    assert [e.settle_s for e in start] == [0.05, 0.05, 0.05, 0.0]  # reference, 6, 7, then 0F
    assert [e.settle_s for e in codec.control(ATV, STOP)] == [0.0]
    (write,) = codec.write(ATV, codec.parameter("hr600"), 0, 1.0, None)
    assert write.settle_s == pytest.approx(0.02)
