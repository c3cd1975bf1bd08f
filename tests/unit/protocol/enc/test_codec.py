"""EncCodec through the DriveCodec seam: what goes on the wire and what replies mean.

Request goldens are the manual's examples (protocols/enc.md §4, §8); their checksums are
worked out in test_frame.py. Reply goldens follow the §3 layout (no source prints a
reply); each checksum is summed by hand beside it ("0"=30 … "9"=39, "A"=41 … "F"=46).
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fcmaster.errors import MalformedReply, ProtocolError, UnexpectedReply, UsageError
from fcmaster.protocol.codec import (
    Access,
    Condition,
    DriveCodec,
    DriveError,
    Exchange,
    ParameterKey,
)
from fcmaster.protocol.drive import ControlIntent, Motion
from fcmaster.protocol.enc import (
    DEFAULT_MONITOR,
    RUNNING_FREQUENCY,
    STATE_WORD,
    EncCodec,
    EncFramer,
    NumberEncoding,
    Response,
    decode_request,
    encode_number,
    encode_response,
)
from tests.unit.protocol.enc.strategies import checked_frames

STATE_POLL = b"~010B000F01A9\r"
FREQUENCY_POLL = b"~010B00010194\r"
STOP = b"~010C0007019B\r"

# Replies of drive 01, summed by hand.
STATE_REVERSE_RUNNING = b"~0100000F0005025C\r"  # "0"×9 = 1B0, +31 = 1E1, +46 = 227, +35 = 25C
STATE_FAULT_10 = b"~0100100F00000258\r"  # "0"×9 = 1B0, "1"×2 = +62 = 212, "F" = +46 = 258
FREQUENCY_40 = b"~010000010FA00269\r"  # "0"×8 = 180, "1"×2 = 1E2, "F" 228, "A" 269
F0_01_50HZ = b"~0100000113880256\r"  # "0"×6 = 120, "1"×3 = 1B3, "3" 1E6, "8" 21E, "8" 256
F0_01_50HZ_06 = b"~010600011388025C\r"  # as above with "6" for a "0": +6 = 25C
REFUSED_PRINTED = b"~013000070000024B\r"  # "0"×9 = 1B0, +31+33+37 = 24B
REFUSED_HEX = b"~011E00070000025E\r"  # "0"×8 = 180, "1"×2 = 1E2, "E" 227, "7" 25E
FRAME_ERROR_HEX = b"~011400C6\r"  # 30+31+31+34 = C6
FRAME_ERROR_PRINTED = b"~012000C3\r"  # 30+31+32+30 = C3
READY_PRINTED = b"~011100000183\r"  # "0"×5 = F0, "1"×3 = +93 = 183
READY_HEX = b"~010B00000193\r"  # "0"×6 = 120, +31 = 151, +42 = 193
COLLIDING_14 = b"~011400000186\r"  # "0"×5 = F0, +31+31+34 = 186
NO_INDEX_NORMAL = b"~010000C1\r"  # 30+31+30+30 = C1


def codec(**options: str) -> EncCodec:
    return EncCodec(**options)  # type: ignore[arg-type]  # the options are all str


def test_enc_codec_is_a_drive_codec() -> None:
    typed: DriveCodec = EncCodec(nominal_hz={1: 60.0})
    assert typed.protocol == "enc"
    assert typed.addresses == range(1, 127)
    assert isinstance(typed.new_framer(), EncFramer)
    assert typed.min_pause_s(0.001) == pytest.approx(0.002)


def test_decimal_addresses_reach_only_1_to_99() -> None:
    assert EncCodec(address_encoding="decimal").addresses == range(1, 100)


def test_unknown_encoding_option_is_a_usage_error() -> None:
    with pytest.raises(UsageError, match="hex or decimal"):
        EncCodec(fault_encoding="bcd")


# ---------------------------------------------------------------- polls


def test_default_monitor_leads_with_the_running_frequency() -> None:
    assert EncCodec().default_monitor() == DEFAULT_MONITOR
    assert DEFAULT_MONITOR[0] == RUNNING_FREQUENCY


def test_poll_sequence_alternates_state_word_and_running_frequency() -> None:
    enc = EncCodec()
    assert enc.poll_sequence(()) == (None, RUNNING_FREQUENCY)
    assert enc.poll_sequence((RUNNING_FREQUENCY, STATE_WORD)) == (None, RUNNING_FREQUENCY)
    current, voltage = enc.parameter("11/0003"), enc.parameter("11/0002")
    assert enc.poll_sequence((RUNNING_FREQUENCY, current, voltage, current)) == (
        None, RUNNING_FREQUENCY, None, current,
        None, RUNNING_FREQUENCY, None, voltage,
    )  # fmt: skip


def test_condition_parameters_are_none_the_fault_comes_in_every_reply() -> None:
    assert EncCodec().condition_parameters(alarms=True, warnings=True) == ()


@pytest.mark.parametrize(
    "intent", [None, ControlIntent(Motion.RUN, reference_pct=50.0)], ids=["monitor", "bus"]
)
def test_status_poll_reads_the_state_word_and_never_commands(
    intent: ControlIntent | None,
) -> None:
    exchange = EncCodec().poll(1, intent, None)
    assert exchange == Exchange(address=1, request=STATE_POLL, reply_length=18)


def test_poll_with_a_read_is_a_parameter_read() -> None:
    exchange = EncCodec().poll(1, None, RUNNING_FREQUENCY)
    assert exchange.request == FREQUENCY_POLL
    assert (exchange.access, exchange.parameter, exchange.carries_control) == (
        Access.READ,
        RUNNING_FREQUENCY,
        False,
    )


@pytest.mark.parametrize(
    ("options", "address", "wire"),
    [
        # "0A": 30+41+30+42 = E3, +30+30+30 = 173, +46 = 1B9
        ({}, 10, b"~0A0B000F01B9\r"),
        # "10": 31+30+30+42 = D3, +30+30+30 = 163, +46 = 1A9
        ({"address_encoding": "decimal"}, 10, b"~100B000F01A9\r"),
        # "7E": 37+45+30+42 = EE, +30+30+30 = 17E, +46 = 1C4
        ({}, 126, b"~7E0B000F01C4\r"),
    ],
    ids=["hex-10", "decimal-10", "hex-126"],
)
def test_address_encoding(options: dict[str, str], address: int, wire: bytes) -> None:
    assert codec(**options).poll(address, None, None).request == wire


@pytest.mark.parametrize(
    ("options", "address"),
    [({}, 127), ({}, -1), ({"address_encoding": "decimal"}, 100)],
    ids=["127", "negative", "decimal-100"],
)
def test_addresses_out_of_range_are_usage_errors(options: dict[str, str], address: int) -> None:
    with pytest.raises(UsageError, match="outside"):
        codec(**options).poll(address, None, None)


# ---------------------------------------------------------------- control


def wires(exchanges: tuple[Exchange, ...]) -> list[bytes]:
    return [exchange.request for exchange in exchanges]


@pytest.mark.parametrize(
    ("intent", "expected"),
    [
        # 80 % of 50 Hz = 40.00 Hz = 0FA0 (§4.2 examples)
        (ControlIntent(Motion.RUN, reference_pct=80.0), [b"~010C00050FA00280\r"]),
        (ControlIntent(Motion.RUN, reverse=True, reference_pct=80.0), [b"~010C00060FA00281\r"]),
        # a negative reference turns the other way
        (ControlIntent(Motion.RUN, reference_pct=-80.0), [b"~010C00060FA00281\r"]),
        (ControlIntent(Motion.RUN, True, -80.0), [b"~010C00050FA00280\r"]),
        # EDS300 table: jog forward 164+39 = 19D, jog reverse 164+41 = 1A5
        (ControlIntent(Motion.JOG), [b"~010C0009019D\r"]),
        (ControlIntent(Motion.JOG, reverse=True), [b"~010C000A01A5\r"]),
        (ControlIntent(Motion.STOP, reference_pct=80.0), [STOP]),
        (ControlIntent(Motion.QUICK_STOP), [b"~010C000D01A8\r"]),
        (ControlIntent(Motion.COAST), [b"~010C000D01A8\r"]),
        (ControlIntent(Motion.STOP, reset=True), [b"~010C000C01A7\r", STOP]),
        (
            ControlIntent(Motion.RUN, reference_pct=80.0, reset=True),
            [b"~010C000C01A7\r", b"~010C00050FA00280\r"],
        ),
    ],
    ids=[
        "run-forward", "run-reverse", "negative-reference", "reverse-negative", "jog",
        "jog-reverse", "stop", "quick-stop", "coast", "reset-stop", "reset-run",
    ],
)  # fmt: skip
def test_control_frames(intent: ControlIntent, expected: list[bytes]) -> None:
    exchanges = EncCodec().control(1, intent)
    assert wires(exchanges) == expected
    for exchange in exchanges:
        assert (exchange.address, exchange.reply_length, exchange.carries_control) == (1, 18, True)
        assert exchange.access is Access.NONE


def test_nominal_frequency_per_address() -> None:
    # 50 % of 60 Hz = 30.00 Hz = 0BB8: "010C0005" sums to 199; 30+42+42+38 = EC; 285
    exchanges = EncCodec(nominal_hz={1: 60.0}).control(1, ControlIntent(Motion.RUN, False, 50.0))
    assert wires(exchanges) == [b"~010C00050BB80285\r"]


def test_broadcast_goes_to_127_and_expects_no_reply() -> None:
    # "7F0C0007": 37+46+30+43 = F0, +30+30+30 = 180, +37 = 1B7
    (exchange,) = EncCodec().control(0, ControlIntent(Motion.STOP))
    assert exchange == Exchange(
        address=0, request=b"~7F0C000701B7\r", reply_length=0, carries_control=True
    )
    assert not exchange.expects_reply


def test_broadcast_needs_the_hex_address_encoding() -> None:
    with pytest.raises(UsageError, match="broadcast"):
        EncCodec(address_encoding="decimal").control(0, ControlIntent(Motion.STOP))


@pytest.mark.parametrize("pct", [1311.0, float("nan"), float("inf")])
def test_frequencies_a_frame_cannot_carry_are_refused_not_clamped(pct: float) -> None:
    # 1311 % of 50 Hz = 655.5 Hz > 655.35 Hz = FFFF × 0.01 Hz
    with pytest.raises(UsageError, match=r"655\.35 Hz"):
        EncCodec().control(1, ControlIntent(Motion.RUN, reference_pct=pct))


def test_highest_frequency_fits() -> None:
    (exchange,) = EncCodec(nominal_hz={1: 655.35}).control(1, ControlIntent(Motion.RUN, False, 100))
    assert decode_request(exchange.request).data == 0xFFFF


@given(
    st.sampled_from(Motion),
    st.booleans(),
    st.floats(-200, 200),
    st.booleans(),
    st.floats(1, 300),
    st.integers(1, 126),
)
def test_control_requests_decode_to_what_the_intent_says(
    motion: Motion, reverse: bool, pct: float, reset: bool, nominal: float, address: int
) -> None:
    intent = ControlIntent(motion, reverse, pct, reset)
    requests = [
        decode_request(e.request)
        for e in EncCodec(nominal_hz={address: nominal}).control(address, intent)
    ]
    assert all((r.address, r.command, r.aux_index) == (address, 12, 0) for r in requests)
    if reset:
        assert (requests[0].cmd_index, requests[0].data) == (0x0C, None)
        requests = requests[1:]
    (main,) = requests
    turning_reverse = reverse != (pct < 0)
    expected = {
        Motion.RUN: 0x06 if turning_reverse else 0x05,
        Motion.JOG: 0x0A if turning_reverse else 0x09,
        Motion.STOP: 0x07,
        Motion.QUICK_STOP: 0x0D,
        Motion.COAST: 0x0D,
    }[motion]
    assert main.cmd_index == expected
    if motion is Motion.RUN:
        assert main.data == round(abs(pct) * nominal)  # % × Hz / 100 in 0.01 Hz steps
    else:
        assert main.data is None


# ---------------------------------------------------------------- read and write


@pytest.mark.parametrize(
    ("name", "wire"),
    [
        ("F0.01", b"~010D00010196\r"),
        ("F0.03", b"~010D00030198\r"),
        ("software_version", b"~010F00000197\r"),
        ("slave_state", b"~010A00000192\r"),
        ("running_frequency", FREQUENCY_POLL),
    ],
)
def test_read_golden_frames(name: str, wire: bytes) -> None:
    enc = EncCodec()
    key = enc.parameter(name)
    (exchange,) = enc.read(1, key, 0, ControlIntent(Motion.RUN, reference_pct=10.0))
    assert exchange == Exchange(
        address=1, request=wire, reply_length=18, access=Access.READ, parameter=key
    )


@pytest.mark.parametrize(
    ("name", "value", "wire"),
    [("F0.01", 50.0, b"~010E00011388026B\r"), ("F0.03", 1, b"~010E00030001025A\r")],
)
def test_write_golden_frames(name: str, value: float, wire: bytes) -> None:
    enc = EncCodec()
    key = enc.parameter(name)
    (exchange,) = enc.write(1, key, 0, value, None, persist=True)
    assert exchange == Exchange(
        address=1, request=wire, reply_length=18, access=Access.WRITE, parameter=key
    )


@pytest.mark.parametrize(
    ("name", "value", "match"),
    [
        ("11/0001", 1.0, "only function codes"),
        ("F0.01", "fast", "numeric"),
        ("F0.01", -0.01, "outside"),
        ("F0.01", 655.36, "outside"),
        ("F0.01", float("nan"), "outside"),
        ("F3.03", 65536, "outside"),
    ],
)
def test_writes_that_cannot_be_carried(name: str, value: float | str, match: str) -> None:
    enc = EncCodec()
    with pytest.raises(UsageError, match=match):
        enc.write(1, enc.parameter(name), 0, value, None)


def test_enc_parameters_have_no_index() -> None:
    enc = EncCodec()
    with pytest.raises(UsageError, match="no array index"):
        enc.read(1, enc.parameter("F0.01"), 1, None)
    with pytest.raises(UsageError, match="no array index"):
        enc.write(1, enc.parameter("F0.01"), 2, 1.0, None)


# ---------------------------------------------------------------- parse


def poll_state(enc: EncCodec, address: int = 1) -> Exchange:
    return enc.poll(address, None, None)


def test_state_word_reply_gives_the_status_and_the_fault_report() -> None:
    reply = EncCodec().parse(poll_state(EncCodec()), STATE_REVERSE_RUNNING)
    assert reply.address == 1
    assert reply.status is not None
    assert (reply.status.word, reply.status.running, reply.status.reverse) == (5, True, True)
    assert (reply.status.fault, reply.status.warning, reply.status.at_reference) == (
        False,
        False,
        False,
    )
    assert reply.conditions is not None
    assert (reply.conditions.kind, reply.conditions.source, reply.conditions.active) == (
        "alarm",
        "failure_index",
        (),
    )
    assert (reply.value, reply.error, reply.output_frequency_hz) == (None, None, None)


def test_state_word_read_on_request_also_gives_the_value() -> None:
    enc = EncCodec()
    reply = enc.parse(enc.read(1, STATE_WORD, 0, None)[0], STATE_REVERSE_RUNNING)
    assert reply.status is not None
    assert reply.value is not None
    assert (reply.value.parameter, reply.value.raw, reply.value.value) == (STATE_WORD, 5, 5.0)


@pytest.mark.parametrize(
    ("fault_encoding", "code", "text"),
    [("hex", 16, "RS-485 communication fault"), ("decimal", 10, "Inverter overheat")],
)
def test_failure_index_is_read_by_the_line_encoding(
    fault_encoding: str, code: int, text: str
) -> None:
    enc = codec(fault_encoding=fault_encoding)
    reply = enc.parse(poll_state(enc), STATE_FAULT_10)
    assert reply.status is not None
    assert reply.status.fault is True
    assert reply.conditions is not None
    assert reply.conditions.active == (Condition(code, text),)


def test_running_frequency_reply() -> None:
    enc = EncCodec()
    reply = enc.parse(enc.poll(1, None, RUNNING_FREQUENCY), FREQUENCY_40)
    assert reply.output_frequency_hz == 40.0
    assert reply.status is None
    assert reply.value is not None
    assert (reply.value.raw, reply.value.value, reply.value.unit) == (4000, 40.0, "Hz")


@pytest.mark.parametrize("wire", [F0_01_50HZ, F0_01_50HZ_06], ids=["00", "06"])
def test_parameter_read_reply_accepts_00_and_06(wire: bytes) -> None:
    enc = EncCodec()
    key = enc.parameter("F0.01")
    reply = enc.parse(enc.read(1, key, 0, None)[0], wire)
    assert reply.value is not None
    assert (reply.value.parameter, reply.value.index, reply.value.raw) == (key, 0, 5000)
    assert (reply.value.value, reply.value.unit) == (50.0, "Hz")


def test_parameter_write_reply_confirms_the_value() -> None:
    enc = EncCodec()
    key = enc.parameter("F0.01")
    reply = enc.parse(enc.write(1, key, 0, 50.0, None)[0], F0_01_50HZ)
    assert reply.value is not None
    assert reply.value.value == 50.0


def test_parameter_write_reply_without_data_confirms_what_was_sent() -> None:
    # "01000001": "0"×6 = 120, "1"×2 = 182
    enc = EncCodec()
    key = enc.parameter("F0.01")
    reply = enc.parse(enc.write(1, key, 0, 50.0, None)[0], b"~010000010182\r")
    assert reply.value is not None
    assert reply.value.raw == 5000


@pytest.mark.parametrize("wire", [REFUSED_PRINTED, REFUSED_HEX], ids=["printed", "hex"])
def test_refusal_30_in_either_reading_is_a_drive_error(wire: bytes) -> None:
    enc = EncCodec()
    reply = enc.parse(enc.control(1, ControlIntent(Motion.STOP))[0], wire)
    assert reply.error is not None
    assert reply.error.code == 30
    assert reply.error.text.startswith("Refused")
    assert reply.conditions is not None


@pytest.mark.parametrize("wire", [FRAME_ERROR_HEX, FRAME_ERROR_PRINTED], ids=["hex", "printed"])
def test_short_frame_error_reply_is_a_drive_error_without_conditions(wire: bytes) -> None:
    enc = EncCodec(response_encoding="decimal")
    reply = enc.parse(poll_state(enc), wire)
    assert reply.error is not None
    assert reply.error == DriveError(20, reply.error.text)
    assert reply.error.text.startswith("Frame error")
    assert reply.conditions is None
    assert reply.status is None


@pytest.mark.parametrize("wire", [READY_PRINTED, READY_HEX], ids=["printed", "hex"])
def test_slave_state_read_gives_the_response_code(wire: bytes) -> None:
    enc = EncCodec()
    key = enc.parameter("slave_state")
    reply = enc.parse(enc.read(1, key, 0, None)[0], wire)
    assert reply.error is None
    assert reply.value is not None
    assert (reply.value.raw, reply.value.value) == (11, 11.0)


def test_the_14_collision_goes_by_the_response_encoding() -> None:
    for options, error, value in (({}, 20, None), ({"response_encoding": "decimal"}, None, 14)):
        enc = codec(**options)
        reply = enc.parse(enc.read(1, enc.parameter("slave_state"), 0, None)[0], COLLIDING_14)
        assert (reply.error and reply.error.code) == error
        assert (reply.value and reply.value.raw) == value


@pytest.mark.parametrize(
    ("wire", "options"),
    [
        # "0A00000F0000": "0"×10 = 1E0, +41+46 = 267
        (b"~0A00000F00000267\r", {}),
        # "1000000F0000": "0"×10 = 1E0, +31+46 = 257
        (b"~1000000F00000257\r", {}),
        (b"~0A00000F00000267\r", {"address_encoding": "decimal"}),
        (b"~1000000F00000257\r", {"address_encoding": "decimal"}),
    ],
    ids=["hex-hex", "hex-decimal", "decimal-hex", "decimal-decimal"],
)
def test_replies_from_address_10_are_accepted_in_either_reading(
    wire: bytes, options: dict[str, str]
) -> None:
    enc = codec(**options)
    assert enc.parse(poll_state(enc, 10), wire).address == 10


def test_reply_from_another_address_is_unexpected() -> None:
    enc = EncCodec()
    with pytest.raises(UnexpectedReply, match="address"):
        enc.parse(poll_state(enc, 2), STATE_REVERSE_RUNNING)


def test_reply_for_another_command_index_is_unexpected() -> None:
    enc = EncCodec()
    with pytest.raises(UnexpectedReply, match="command index 01"):
        enc.parse(poll_state(enc), FREQUENCY_40)


def test_reply_to_a_broadcast_is_unexpected() -> None:
    enc = EncCodec()
    (broadcast,) = enc.control(0, ControlIntent(Motion.STOP))
    with pytest.raises(UnexpectedReply, match="gets none"):
        enc.parse(broadcast, STATE_REVERSE_RUNNING)


@pytest.mark.parametrize(
    ("wire", "match"),
    [
        (STATE_REVERSE_RUNNING[:-2] + b"D\r", "checksum"),
        (READY_HEX, "response code 0B"),  # "0B" answers command 10, not 11
        (NO_INDEX_NORMAL, "without index area"),
        # "0100000F": no data area: "0"×6 = 120, +31 = 151, +46 = 197
        (b"~0100000F0197\r", "no data area"),
    ],
    ids=["checksum", "foreign-code", "no-index", "no-data"],
)
def test_malformed_replies(wire: bytes, match: str) -> None:
    enc = EncCodec()
    with pytest.raises(MalformedReply, match=match) as caught:
        enc.parse(poll_state(enc), wire)
    assert caught.value.raw == wire


# ---------------------------------------------------------------- properties

encodings = st.sampled_from([str(e) for e in NumberEncoding])


@given(encodings, encodings, encodings, st.data())
@settings(max_examples=200)
def test_replies_encoded_the_lines_way_decode_back(
    address_encoding: str, response_encoding: str, fault_encoding: str, data: st.DataObject
) -> None:
    # The simulator's side: encode a state-word reply with the line's encodings, parse it.
    enc = codec(
        address_encoding=address_encoding,
        response_encoding=response_encoding,
        fault_encoding=fault_encoding,
    )
    address = data.draw(st.sampled_from(enc.addresses))
    word = data.draw(st.integers(0, 0xFFFF))
    fault = data.draw(st.integers(0, 23))
    refused = data.draw(st.booleans())
    wire = encode_response(
        Response(
            address=encode_number(address, NumberEncoding(address_encoding)),
            response=encode_number(30 if refused else 0, NumberEncoding(response_encoding)),
            failure_index=encode_number(fault, NumberEncoding(fault_encoding)),
            cmd_index=0x0F,
            data=word,
        )
    )
    reply = enc.parse(poll_state(enc, address), wire)
    assert reply.address == address
    assert reply.conditions is not None
    assert [c.code for c in reply.conditions.active] == ([fault] if fault else [])
    if refused:
        assert reply.error is not None
        assert reply.error.code == 30
    else:
        assert reply.status is not None
        assert (reply.status.word, reply.status.fault) == (word, fault != 0)


def exchanges_of(enc: EncCodec) -> st.SearchStrategy[Exchange]:
    keys: list[ParameterKey | None] = [
        None,
        *DEFAULT_MONITOR,
        STATE_WORD,
        enc.parameter("F0.01"),
        enc.parameter("slave_state"),
        enc.parameter("software_version"),
    ]
    polls = st.builds(enc.poll, st.integers(1, 9), st.none(), st.sampled_from(keys))
    controls = st.builds(
        lambda address, motion, reset: enc.control(address, ControlIntent(motion, reset=reset))[0],
        st.integers(0, 9),
        st.sampled_from(Motion),
        st.booleans(),
    )
    writes = st.builds(
        lambda address: enc.write(address, enc.parameter("F0.03"), 0, 1, None)[0],
        st.integers(1, 9),
    )
    return polls | controls | writes


@given(st.data(), encodings, encodings, checked_frames | st.binary(max_size=20))
@settings(max_examples=400)
def test_parse_raises_only_protocol_errors(
    data: st.DataObject, response_encoding: str, fault_encoding: str, frame: bytes
) -> None:
    enc = codec(response_encoding=response_encoding, fault_encoding=fault_encoding)
    exchange = data.draw(exchanges_of(enc))
    try:
        reply = enc.parse(exchange, frame)
    except ProtocolError:
        return
    assert reply.address == exchange.address


def test_software_version_reply_is_a_raw_value() -> None:
    # "010000000123": "0"×8 = 180, "1"×2 = 1E2, +32 = 214, +33 = 247
    enc = EncCodec()
    key = enc.parameter("software_version")
    reply = enc.parse(enc.read(1, key, 0, None)[0], b"~0100000001230247\r")
    assert reply.value is not None
    assert (reply.value.raw, reply.value.unit) == (0x0123, "")
