"""The simulated ENC drive answers "~" frames as protocols/enc.md says, in virtual time."""

from __future__ import annotations

import pytest

from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.errors import MalformedReply
from fcmaster.protocol.enc import (
    EncCodec,
    Response,
    StateWord,
    decode_response,
    encode_request,
)
from fcmaster.protocol.enc.frame import Request
from fcmaster.protocol.framing import Frame
from fcmaster.sim import DriveSettings, FaultPlan, LineSettings, SimLine, build_line
from fcmaster.sim.enc import COMMUNICATION_FAULT, EncRequestFramer, EncSimDrive
from fcmaster.sim.service import sim_line
from tests.fakes import FakeClock

# Frames printed in the manuals (protocols/enc.md §4, §8), slave 01.
LOOK_UP_STATE = b"~010A00000192\r"
READ_STATE_WORD = b"~010B000F01A9\r"
READ_FREQUENCY = b"~010B00010194\r"
FORWARD_40HZ = b"~010C00050FA00280\r"
REVERSE_40HZ = b"~010C00060FA00281\r"
STOP = b"~010C0007019B\r"
FAULT_RESET = b"~010C000C01A7\r"
EMERGENCY_STOP = b"~010C000D01A8\r"
READ_F0_01 = b"~010D00010196\r"
WRITE_F0_01_50HZ = b"~010E00011388026B\r"


def request(
    address: int, command: int, index: int = 0, data: int | None = None, aux: int = 0
) -> bytes:
    """A request with a 16-bit ``index`` (auxiliary index high, command index low)."""
    aux_index = aux or index >> 8
    return encode_request(
        Request(
            address=address, command=command, aux_index=aux_index, cmd_index=index & 0xFF,
            data=data,
        )
    )  # fmt: skip


class Bench:
    """ENC drives on one line, driven frame by frame in virtual time."""

    def __init__(
        self,
        addresses: tuple[int, ...] = (1,),
        *,
        settings: DriveSettings | None = None,
        faults: FaultPlan | None = None,
        address_encoding: str = "hex",
        response_encoding: str = "hex",
        fault_encoding: str = "hex",
    ) -> None:
        self.clock = FakeClock()
        ramps = DriveSettings(parameters={"F0.08": 1.0, "F0.09": 1.0}, max_frequency_hz=50.0)
        self.line: SimLine = build_line(
            LineSettings(
                protocol="enc",
                baudrate=9600,
                parity="N",
                faults=faults or FaultPlan(),
                protocol_options=(
                    ("address_encoding", address_encoding),
                    ("response_encoding", response_encoding),
                    ("fault_encoding", fault_encoding),
                ),
            ),
            [(a, settings or ramps) for a in addresses],
            clock=self.clock,
        )

    def drive(self, address: int = 1) -> EncSimDrive:
        found = next(d for d in self.line.drives if d.address == address)
        assert isinstance(found, EncSimDrive)
        return found

    def send(self, frame: bytes) -> bytes:
        """Write ``frame`` now; move the clock past the reply; what reached the master."""
        self.line.write(frame)
        out = b""
        while (due := self.line.next_delivery()) is not None:
            self.clock.time = max(self.clock.time, due)
            out += self.line.receive()
        return out

    def ask(self, frame: bytes) -> Response:
        return decode_response(self.send(frame))

    def wait(self, seconds: float) -> None:
        self.clock.time += seconds

    def state_word(self, address: int = 1) -> int:
        data = self.ask(request(address, 11, 0x0F)).data
        assert data is not None
        return data

    def frequency_hz(self, address: int = 1) -> float:
        data = self.ask(request(address, 11, 0x01)).data
        assert data is not None
        return data / 100


# -- bytes on the wire -----------------------------------------------------------------------


def test_look_up_state_answers_ready_with_control_as_its_response_code() -> None:
    # 11 (ready, control and frequency allowed), hex-encoded like the commands: "0B".
    assert Bench().send(LOOK_UP_STATE) == b"~010B000000000253\r"


def test_decimal_response_encoding_writes_the_printed_digits() -> None:
    assert Bench(response_encoding="decimal").send(LOOK_UP_STATE) == b"~0111000000000243\r"


def test_a_stopped_drive_reports_a_zero_state_word_and_no_fault() -> None:
    assert Bench().send(READ_STATE_WORD) == b"~0100000F00000257\r"


def test_run_control_reply_echoes_the_index_and_the_frequency() -> None:
    assert Bench().send(FORWARD_40HZ) == b"~010000050FA0026D\r"


def test_parameter_write_reply_confirms_the_value() -> None:
    bench = Bench()
    assert bench.send(WRITE_F0_01_50HZ) == b"~0100000113880256\r"
    assert bench.ask(READ_F0_01).data == 5000


def test_a_wrong_checksum_gets_the_short_frame_error_reply() -> None:
    damaged = READ_STATE_WORD[:-5] + b"01AA\r"
    # §5: response 20 ("14" in hex) with command, index and data areas left out.
    assert Bench().send(damaged) == b"~011400C6\r"
    assert Bench(response_encoding="decimal").send(damaged) == b"~012000C3\r"


@pytest.mark.parametrize(
    ("frame", "why"),
    [
        (request(1, 0x10), "command 16 is not one of 10-15"),
        (request(1, 11, 0x10), "no running value 0010"),
        (request(1, 12, 0x0E), "no run-control index 000E"),
        (request(1, 13, 0x0107), "no function code F1.07 in the simulator"),
        (request(1, 11, 0x01, data=5), "command 11 carries no data"),
        (request(1, 12, 0x05), "run with frequency needs its data"),
        (request(1, 10, 0x01), "command 10 takes index 0000"),
        (request(1, 11, 0x01, aux=1), "command 11 has no auxiliary index"),
    ],
)
def test_fields_out_of_range_are_frame_errors(frame: bytes, why: str) -> None:
    reply = Bench().ask(frame)
    assert reply.response == 0x14, why
    assert reply.failure_index is None


def test_another_drives_frames_get_no_answer() -> None:
    bench = Bench((1, 2))
    assert bench.send(request(3, 11, 0x0F)) == b""
    assert bench.ask(request(2, 11, 0x0F)).address == 2


def test_hex_and_decimal_address_encodings() -> None:
    assert Bench((12,)).ask(request(0x0C, 11, 0x0F)).address == 0x0C
    decimal = Bench((12,), address_encoding="decimal")
    assert decimal.send(request(0x0C, 11, 0x0F)) == b""  # "0C" is not how it writes 12
    assert decimal.ask(request(0x12, 11, 0x0F)).address == 0x12


def test_a_broadcast_is_obeyed_and_never_answered() -> None:
    bench = Bench((1, 2))
    for address in (1, 2):
        bench.send(request(address, 12, 0x05, data=2000))
    bench.wait(2.0)
    assert bench.frequency_hz(1) == bench.frequency_hz(2) == 20.0  # both running first
    assert bench.send(request(127, 12, 0x07)) == b""
    bench.wait(2.0)
    assert bench.frequency_hz(1) == bench.frequency_hz(2) == 0.0


def test_replies_leave_after_the_response_delay() -> None:
    bench = Bench()
    bench.send(READ_STATE_WORD)
    record = bench.line.transactions[-1]
    assert record.reply_start is not None
    assert record.reply_start - record.request_end == pytest.approx(0.005)  # F2.17 default
    assert bench.ask(request(1, 14, 0x0211, data=20)).response == 0  # F2.17 = 20 ms
    bench.send(READ_STATE_WORD)
    record = bench.line.transactions[-1]
    assert record.reply_start is not None
    assert record.reply_start - record.request_end == pytest.approx(0.020)


# -- running state and values ---------------------------------------------------------------


def test_forward_run_with_frequency_ramps_and_reports_running() -> None:
    bench = Bench()
    assert bench.ask(FORWARD_40HZ).response == 0
    bench.wait(0.4)  # F0.08 = 1.0 s from 0 to 50 Hz: 20 Hz after 0.4 s, and the reply's time
    assert 20.0 <= bench.frequency_hz() <= 23.0
    bench.wait(1.0)
    assert bench.frequency_hz() == 40.0
    word = bench.state_word()
    assert word & StateWord.RUNNING
    assert word & StateWord.NORMAL_RUN
    assert not word & StateWord.REVERSE
    assert bench.ask(request(1, 11, 0x00)).data == 4000  # set frequency
    assert bench.ask(request(1, 11, 0x02)).data == 320  # V/f: 400 V × 40/50


def test_reverse_run_sets_the_reverse_bit() -> None:
    bench = Bench()
    bench.send(REVERSE_40HZ)
    bench.wait(2.0)
    assert bench.state_word() & StateWord.REVERSE
    assert bench.frequency_hz() == 40.0  # a magnitude on the wire
    assert bench.drive().motor.frequency_hz == -40.0


def test_stop_ramps_down_and_emergency_stop_cuts_the_output() -> None:
    bench = Bench()
    bench.send(FORWARD_40HZ)
    bench.wait(2.0)
    bench.send(STOP)
    bench.wait(0.2)
    assert 25.0 < bench.frequency_hz() < 35.0  # ramping down at 50 Hz/s
    assert bench.state_word() & StateWord.RUNNING
    bench.send(EMERGENCY_STOP)
    assert bench.frequency_hz() == 0.0
    assert not bench.state_word() & StateWord.RUNNING
    bench.send(request(1, 12, 0x00))  # run again at the set frequency
    bench.wait(2.0)
    assert bench.frequency_hz() == 40.0


def test_set_frequency_changes_speed_without_starting() -> None:
    bench = Bench()
    bench.send(request(1, 12, 0x01, data=2500))
    bench.wait(1.0)
    assert bench.frequency_hz() == 0.0
    bench.send(request(1, 12, 0x03))  # forward run at the set frequency
    bench.wait(1.0)
    assert bench.frequency_hz() == 25.0


def test_jog_runs_at_the_jog_frequency_and_sets_the_jog_bit() -> None:
    bench = Bench()
    bench.send(request(1, 12, 0x0A))  # jog reverse
    bench.wait(1.0)
    word = bench.state_word()
    assert word & StateWord.JOGGING
    assert word & StateWord.REVERSE
    assert not word & StateWord.NORMAL_RUN
    assert bench.frequency_hz() == 5.0
    bench.send(request(1, 12, 0x0B))  # stop jog
    bench.wait(1.0)
    assert bench.frequency_hz() == 0.0


def test_a_drive_found_running_reports_it() -> None:
    bench = Bench(settings=DriveSettings(running_hz=30.0))
    assert bench.state_word() & StateWord.RUNNING
    assert bench.frequency_hz() == pytest.approx(30.0)


def test_a_warning_cycle_shows_as_undervoltage() -> None:
    bench = Bench(settings=DriveSettings(warning_cycle=(1, 10.0, 2.0)))
    assert bench.state_word() & StateWord.UNDERVOLTAGE
    bench.wait(5.0)
    assert not bench.state_word() & StateWord.UNDERVOLTAGE


def test_codec_reads_the_simulators_replies() -> None:
    """The master's codec and the simulated drive agree, value for value."""
    bench = Bench()
    codec = EncCodec()
    bench.send(FORWARD_40HZ)
    bench.wait(2.0)
    poll = codec.poll(1, None, None)
    status = codec.parse(poll, bench.send(poll.request)).status
    assert status is not None
    assert status.running
    assert not status.fault
    assert status.reverse is False
    frequency = codec.poll(1, None, codec.parameter("running_frequency"))
    assert codec.parse(frequency, bench.send(frequency.request)).output_frequency_hz == 40.0


# -- refusals, faults and the watchdog ------------------------------------------------------


def test_a_frequency_beyond_the_upper_limit_is_refused_not_clamped() -> None:
    bench = Bench()
    reply = bench.ask(request(1, 12, 0x05, data=5001))  # 50.01 Hz > 50 Hz upper limit
    assert reply.response == 0x1E  # 30, hex-encoded
    bench.wait(1.0)
    assert bench.frequency_hz() == 0.0
    assert bench.ask(request(1, 11, 0x00)).data == 5000  # the set frequency is untouched


def test_a_drive_in_local_operation_refuses_control_and_says_so() -> None:
    bench = Bench(settings=DriveSettings(local=True))
    assert bench.ask(LOOK_UP_STATE).response == 13  # ready, control not allowed
    assert bench.ask(FORWARD_40HZ).response == 0x1E
    assert bench.ask(STOP).response == 0x1E
    bench.wait(1.0)
    assert bench.frequency_hz() == 0.0


def test_parameter_writes_out_of_range_or_while_running_are_refused() -> None:
    bench = Bench()
    assert bench.ask(request(1, 14, 0x0008, data=0)).response == 0x1E  # F0.08 below 0.1 s
    assert bench.ask(request(1, 14, 0x0003, data=2)).response == 0x1E  # F0.03 is 0 or 1
    bench.send(FORWARD_40HZ)
    assert bench.ask(request(1, 14, 0x0210, data=10)).response == 0x1E  # F2.16 while running
    bench.send(STOP)
    bench.wait(2.0)
    assert bench.ask(request(1, 14, 0x0210, data=10)).response == 0
    assert bench.ask(request(1, 13, 0x0210)).data == 10


def test_writing_the_local_address_moves_the_drive() -> None:
    bench = Bench()
    assert bench.ask(request(1, 14, 0x020F, data=9)).response == 0
    assert bench.send(READ_STATE_WORD) == b""
    assert bench.ask(request(9, 11, 0x0F)).address == 9


def test_a_trip_stops_the_motor_and_refuses_runs_until_reset() -> None:
    bench = Bench()
    bench.send(FORWARD_40HZ)
    bench.wait(2.0)
    drive = bench.drive()
    drive.control.raise_fault(9, bench.clock.now())  # motor overload
    reply = bench.ask(READ_FREQUENCY)
    assert reply.failure_index == 9
    assert reply.data == 0
    assert bench.ask(LOOK_UP_STATE).response == 10  # not ready
    assert bench.ask(FORWARD_40HZ).response == 0x1E
    assert bench.ask(FAULT_RESET).response == 0x1E  # its cause is still there
    drive.control.clear_fault(9, bench.clock.now())
    assert bench.ask(FAULT_RESET) == Response(
        address=1, response=0, failure_index=0, cmd_index=0x0C, data=0
    )
    bench.wait(1.0)
    assert bench.frequency_hz() == 0.0  # a reset does not restart the motor


def test_fault_codes_follow_the_fault_encoding() -> None:
    for encoding, field in (("hex", 0x10), ("decimal", 0x16)):
        bench = Bench(fault_encoding=encoding)
        bench.drive().control.raise_fault(16, bench.clock.now())
        assert bench.ask(READ_STATE_WORD).failure_index == field


def test_the_communication_watchdog_trips_with_fault_16() -> None:
    bench = Bench()
    assert bench.ask(request(1, 14, 0x0210, data=5)).response == 0  # F2.16 = 0.5 s
    bench.send(FORWARD_40HZ)
    bench.wait(0.4)
    assert bench.ask(READ_STATE_WORD).failure_index == 0  # fed in time
    bench.wait(0.6)
    reply = bench.ask(READ_STATE_WORD)
    assert reply.failure_index == COMMUNICATION_FAULT  # hex "10"
    assert reply.data is not None
    assert not reply.data & StateWord.RUNNING
    assert bench.ask(FAULT_RESET).response == 0  # heard again, so the cause is gone
    assert bench.ask(READ_STATE_WORD).failure_index == 0


def test_the_watchdog_is_off_by_default() -> None:
    bench = Bench()
    bench.send(FORWARD_40HZ)
    bench.wait(60.0)
    assert bench.ask(READ_STATE_WORD).failure_index == 0
    assert bench.frequency_hz() == 40.0


def test_a_dropped_reply_still_leaves_the_command_obeyed() -> None:
    bench = Bench(faults=FaultPlan(drop=1.0))
    assert bench.send(FORWARD_40HZ) == b""
    assert bench.line.counters.dropped == 1
    bench.wait(2.0)
    drive = bench.drive()
    drive.advance(bench.clock.now())
    assert drive.motor.frequency_hz == 40.0


def test_a_corrupted_reply_fails_the_masters_checksum() -> None:
    bench = Bench(faults=FaultPlan(corrupt=1.0, seed=5))
    data = bench.send(READ_STATE_WORD)
    assert len(data) == 18
    with pytest.raises(MalformedReply):
        decode_response(data)


def test_the_drives_framer_passes_damaged_frames_to_the_drive() -> None:
    framer = EncRequestFramer()
    framer.feed(b"~010B000F01AA\r~01\r")
    assert framer.next_frame() == Frame(b"~010B000F01AA\r")
    piece = framer.next_frame()
    assert piece is not None
    assert not isinstance(piece, Frame)


# -- configuration ---------------------------------------------------------------------------


def test_a_sim_line_from_config_honours_the_encodings_and_nominal_frequency() -> None:
    plan = LinePlan(
        name="enc1", port="sim://enc1", protocol="enc", baudrate=19200, parity="N",
        address_encoding="decimal", response_encoding="decimal", fault_encoding="decimal",
        drives=(DrivePlan(name="fan", address=12, nominal_frequency_hz=60.0,
                          max_frequency_hz=60.0),),
    )  # fmt: skip
    clock = FakeClock()
    line = sim_line(plan, {"drives": {12: {"parameters": {"F0.08": 2.0}}}}, clock=clock)
    (drive,) = line.drives
    assert isinstance(drive, EncSimDrive)
    assert drive.parameters[0x020E] == 4  # F2.14: 19200 8N1
    assert drive.parameters[0x0008] == 20
    assert drive.parameters.upper_limit_hz == pytest.approx(78.0)  # 1.3 × nominal
    line.write(request(0x12, 10))
    clock.time += 1.0
    assert decode_response(line.receive()).response == 0x11  # "11", the printed digits


def test_exported_names_exist() -> None:
    import fcmaster.sim.enc

    for name in fcmaster.sim.enc.__all__:
        assert hasattr(fcmaster.sim.enc, name), name
    assert sorted(fcmaster.sim.enc.__all__) == sorted(set(fcmaster.sim.enc.__all__))
    assert fcmaster.sim.EncSimDrive is EncSimDrive
