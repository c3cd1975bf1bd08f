"""The simulated Mitsubishi inverter, byte by byte, in virtual time.

Requests are built with the codec's encoder or spelled out by hand with their sums in the
comments ("0"=48 "1"=49 "7"=55 "A"=65 "F"=70 …), so a test fails if the drive and the
protocol document disagree.
"""

from __future__ import annotations

import pytest

from fcmaster.errors import UsageError
from fcmaster.protocol.mitsubishi import (
    Ack,
    DataReply,
    MitsubishiCodec,
    Nak,
    Request,
    StatusBits,
    Terminator,
    decode_frame,
    encode_frame,
)
from fcmaster.sim import DriveSettings, LineSettings, MitsubishiSimDrive, SimLine, build_line
from fcmaster.sim.mitsubishi.drive import DEFAULT_CHECK_S, PARAMETER_EXTRA_S, RESTART_S
from tests.fakes import FakeClock

ST = StatusBits


class Bench:
    """Mitsubishi drives on a line at 19200 8E2, talked to one request at a time."""

    def __init__(
        self,
        *addresses: int,
        terminator: Terminator = Terminator.CR,
        wait_digit: bool = True,
        parameters: dict[str, float] | None = None,
        local: bool = False,
        running_hz: float | None = None,
        warning_cycle: tuple[int, float, float] | None = None,
    ) -> None:
        self.clock = FakeClock()
        self.terminator = terminator
        parameters = dict(parameters or {})
        parameters["Pr.124"] = float(list(Terminator).index(terminator))
        if not wait_digit:
            parameters.setdefault("Pr.123", 0.0)
        drive = DriveSettings(
            parameters=parameters, local=local, running_hz=running_hz, warning_cycle=warning_cycle
        )
        self.line: SimLine = build_line(
            LineSettings(protocol="mitsubishi", stopbits=2),
            [(a, drive) for a in addresses or (1,)],
            clock=self.clock,
        )
        self.wait_ms: int | None = 0 if wait_digit else None

    def drive(self, address: int = 1) -> MitsubishiSimDrive:
        found = next(d for d in self.line.drives if d.address == address)
        assert isinstance(found, MitsubishiSimDrive)
        return found

    def raw(self, request: bytes) -> bytes:
        """Write ``request`` now; what reached the master by the end of the reply."""
        self.line.write(request)
        out = b""
        while (due := self.line.next_delivery()) is not None:
            self.clock.time = max(self.clock.time, due)
            out += self.line.receive()
        self.clock.time += 0.010  # the master's turnaround (§2)
        return out

    def request(
        self, code: int, data: int | None = None, width: int = 0, station: int = 1
    ) -> bytes:
        message = Request(station=station, instruction=code, data=data, width=width,
                          wait_ms=self.wait_ms)  # fmt: skip
        return self.raw(encode_frame(message, self.terminator))

    def read(self, code: int, station: int = 1) -> int:
        reply = decode_frame(self.request(code, station=station))
        assert isinstance(reply, DataReply), reply
        assert reply.data is not None
        return reply.data

    def write(self, code: int, data: int, width: int = 4) -> Ack | Nak:
        reply = decode_frame(self.request(code, data, width))
        assert isinstance(reply, Ack | Nak), reply
        return reply

    def parameter(self, number: int, value: int | None = None) -> int | Ack | Nak:
        """Read (value None) or write Pr.``number`` the way the master does: page, then code."""
        assert self.write(0xFF, number // 100, 2) == Ack(1)
        if value is None:
            return self.read(number % 100)
        return self.write(0x80 + number % 100, value)

    def run_for(self, seconds: float) -> None:
        self.clock.time += seconds


def nak(code: int, station: int = 1) -> Nak:
    return Nak(station, code)


# -- the wire -----------------------------------------------------------------------------


def test_status_read_golden_bytes() -> None:
    bench = Bench(1)
    # request 48+49+55+65+48 = 265 -> "09"; reply "0100": 48+49+48+48 = 193 -> "C1"
    assert bench.raw(b"\x05017A009\r") == b"\x020100\x03C1\r"


def test_only_the_addressed_station_answers_and_station_0_is_a_drive() -> None:
    bench = Bench(0, 10)
    assert bench.read(0x7A, station=10) == 0
    assert bench.read(0x7A, station=0) == 0
    assert bench.request(0x7A, station=16) == b""  # "10" is station 16, nobody there
    assert bench.line.counters.replies == 2


def test_terminator_follows_pr124() -> None:
    bench = Bench(1, terminator=Terminator.CRLF)
    assert bench.raw(b"\x05017A009\r\n") == b"\x020100\x03C1\r\n"
    none = Bench(1, terminator=Terminator.NONE)
    assert none.raw(b"\x05017A009") == b"\x020100\x03C1"


def test_without_the_waiting_digit_when_pr123_sets_the_time() -> None:
    bench = Bench(1, wait_digit=False, parameters={"Pr.123": 30.0})
    # 48+49+55+65 = 217 = 0xD9
    assert bench.raw(b"\x05017AD9\r") == b"\x020100\x03C1\r"
    record = bench.line.transactions[-1]
    assert record.reply_start is not None
    assert record.reply_start - record.request_end == pytest.approx(0.030 + DEFAULT_CHECK_S)


def test_the_waiting_digit_delays_the_reply() -> None:
    bench = Bench(1)
    bench.wait_ms = 50
    assert bench.read(0x7A) == 0
    record = bench.line.transactions[-1]
    assert record.reply_start is not None
    assert record.reply_start - record.request_end == pytest.approx(0.050 + DEFAULT_CHECK_S)
    bench.wait_ms = 0
    bench.parameter(7)
    record = bench.line.transactions[-1]
    assert record.reply_start is not None
    slow = DEFAULT_CHECK_S + PARAMETER_EXTRA_S  # a parameter read checks longer (§7)
    assert record.reply_start - record.request_end == pytest.approx(slow)


@pytest.mark.parametrize(
    ("frame", "code"),
    [
        (b"\x05017A00A\r", 2),  # the sum check is 09
        (b"\x05017a029\r", 7),  # lowercase "a" (48+49+55+97+48 = 0x129): character error
        (b"\x05017A0\r", 3),  # too short for any format
        (b"\x0501ED009C4F00\r", 3),  # a frequency write with five data digits
        (b"\x050178000\r", 0xB),  # H78 does not exist: 48+49+55+56+48 = 256 = 0x100
    ],
    ids=["sum", "character", "short", "width", "no-such-code"],
)
def test_broken_requests_get_their_error_code(frame: bytes, code: int) -> None:
    bench = Bench(1, parameters={"Pr.121": 9999.0})
    assert decode_frame(bench.raw(frame)) == nak(code)


def test_a_terminator_other_than_pr124_is_a_protocol_error() -> None:
    # The line's receiver cuts by the line's terminator, so a drive set otherwise (here
    # Pr.124 = 1, CR) is shown a frame with CR LF directly.
    bench = Bench(1, parameters={"Pr.121": 9999.0})  # never trip on reception errors
    drive, now = bench.drive(), bench.clock.now()
    reply = drive.handle(b"\x05017A009\r\n", now)
    assert reply is not None
    assert decode_frame(reply) == nak(3)
    assert drive.handle(b"\x05017A009", now + 0.1) == encode_frame(nak(3), Terminator.CR)


def test_consecutive_reception_errors_beyond_pr121_trip_the_drive() -> None:
    bench = Bench(1)  # Pr.121 = 1: one error is allowed, the second trips
    assert decode_frame(bench.raw(b"\x05017A00A\r")) == nak(2)
    assert bench.read(0x7A) & ST.ABC1 == 0  # a good request ends the run
    assert decode_frame(bench.raw(b"\x05017A00A\r")) == nak(2)
    assert decode_frame(bench.raw(b"\x05017A00A\r")) == nak(0)  # computer NAK: tripped
    assert bench.read(0x7A) & ST.ABC1
    assert bench.read(0x74) & 0xFF == 0xB1  # E.PUE


def test_character_errors_do_not_count_toward_the_pr121_trip() -> None:
    bench = Bench(1)  # Pr.121 = 1
    for _ in range(3):  # lowercase "a": error 7, which §5 leaves out of the count
        assert decode_frame(bench.raw(b"\x05017a029\r")) == nak(7)
    assert bench.read(0x7A) & ST.ABC1 == 0  # not tripped


def test_run_commands_to_a_tripped_drive_add_no_history() -> None:
    bench = Bench(1, parameters={"Pr.122": 0.0})  # Pr.122 = 0: a link run command trips
    assert bench.write(0xFA, 0x02, 2) == Ack(1)
    assert bench.read(0x74) & 0xFF == 0xB1  # E.PUE, latest in the history
    assert bench.write(0xFA, 0x02, 2) == Ack(1)
    assert bench.read(0x74) >> 8 != 0xB1  # the same trip, not a second entry


# -- running ------------------------------------------------------------------------------


def test_run_command_ramps_to_the_set_frequency_and_reports_it() -> None:
    bench = Bench(1)
    assert bench.write(0xED, 5000) == Ack(1)  # 50.00 Hz to RAM
    assert bench.write(0xFA, 0x02, 2) == Ack(1)  # STF
    status = bench.read(0x7A)
    assert status & (ST.RUN | ST.FORWARD) == ST.RUN | ST.FORWARD
    assert not status & ST.SU
    bench.run_for(2.5)  # Pr.7 = 5 s from 0 to 50 Hz
    assert bench.read(0x6F) == pytest.approx(2500, abs=100)  # plus the transactions' time
    bench.run_for(3.0)
    assert bench.read(0x6F) == 5000
    assert bench.read(0x7A) == ST.RUN | ST.FORWARD | ST.SU | ST.FU
    assert bench.read(0x70) > 0  # output current, 0.01 A
    assert bench.read(0x71) == 4000  # 400.0 V at rated frequency, 0.1 V
    assert bench.read(0x6D) == 5000
    assert bench.write(0xFA, 0x00, 2) == Ack(1)  # stop: decelerate on Pr.8
    bench.run_for(6.0)
    assert bench.read(0x6F) == 0
    assert bench.read(0x7A) == 0


def test_reverse_and_output_stop() -> None:
    bench = Bench(1)
    bench.write(0xED, 3000)
    bench.write(0xFA, 0x04, 2)  # STR
    bench.run_for(5.0)
    assert bench.read(0x7A) & (ST.RUN | ST.REVERSE | ST.FORWARD) == ST.RUN | ST.REVERSE
    assert bench.read(0x6F) == 3000  # the monitor shows the magnitude
    bench.write(0xFA, 0x80, 2)  # MRS: output off at once, the motor coasts
    assert bench.read(0x6F) == 0
    assert bench.read(0x7A) & ST.RUN == 0


def test_frequency_beyond_pr1_is_a_data_range_error_and_never_clamped() -> None:
    bench = Bench(1, parameters={"Pr.1": 60.0})
    assert bench.write(0xED, 6001) == nak(0xC)
    assert bench.read(0x6D) == 0
    assert bench.write(0xED, 6000) == Ack(1)


def test_eeprom_frequency_survives_a_reset_and_ram_does_not() -> None:
    bench = Bench(1)
    bench.write(0xEE, 4000)
    bench.write(0xED, 2000)
    assert (bench.read(0x6D), bench.read(0x6E)) == (2000, 4000)
    assert bench.request(0xFD, 0x9696, 4) == b""
    bench.run_for(RESTART_S)
    assert bench.read(0x6D) == 4000


def test_a_local_drive_refuses_commands_with_a_mode_error() -> None:
    bench = Bench(1, local=True)
    assert bench.read(0x7B) == 1  # external operation
    assert bench.write(0xFA, 0x02, 2) == nak(0xA)
    assert bench.write(0xFB, 0x0000) == nak(0xA)
    assert bench.read(0x7A) == 0  # monitoring still works


def test_operation_mode_can_be_changed_while_stopped_only() -> None:
    bench = Bench(1)
    assert bench.read(0x7B) == 0  # network operation (Pr.340 = 1 in the simulator)
    assert bench.write(0xFB, 0x0001) == Ack(1)
    assert bench.write(0xFA, 0x02, 2) == nak(0xA)  # no longer the command source
    assert bench.write(0xFB, 0x0003) == nak(0xC)
    bench.write(0xFB, 0x0000)
    bench.write(0xED, 1000)
    bench.write(0xFA, 0x02, 2)
    assert bench.write(0xFB, 0x0001) == nak(0xA)  # running


def test_a_drive_found_running_reports_it() -> None:
    bench = Bench(1, running_hz=35.0)
    assert bench.read(0x6F) == 3500
    assert bench.read(0x7A) & (ST.RUN | ST.FORWARD | ST.SU) == ST.RUN | ST.FORWARD | ST.SU


def test_an_injected_warning_shows_as_overload() -> None:
    bench = Bench(1, warning_cycle=(0, 10.0, 2.0))
    assert bench.read(0x7A) & ST.OL
    bench.run_for(3.0)
    assert not bench.read(0x7A) & ST.OL


# -- parameters ---------------------------------------------------------------------------


def test_parameters_read_and_write_through_the_page() -> None:
    bench = Bench(1)
    assert bench.parameter(7) == 50  # 5.0 s
    assert bench.parameter(7, 25) == Ack(1)
    assert bench.parameter(7) == 25
    assert bench.parameter(122) == 0xFFFF  # 9999: no check
    assert bench.read(0x7F) == 1  # the page is drive state


def test_parameter_refusals() -> None:
    bench = Bench(1)
    assert bench.parameter(7, 36001) == nak(0xC)  # beyond 3600.0 s
    assert bench.parameter(123, 15) == nak(0xC)  # 10 ms steps
    bench.write(0xFF, 0, 2)
    assert decode_frame(bench.request(0x0A)) == nak(0xB)  # Pr.10: not one this drive has
    assert bench.write(0xFF, 0x0A, 2) == nak(0xC)  # no page 10
    bench.write(0xED, 1000)
    bench.write(0xFA, 0x02, 2)
    assert bench.parameter(1, 6000) == nak(0xA)  # only while stopped
    assert bench.parameter(7, 30) == Ack(1)  # ramp times may change while running


def test_codec_and_drive_agree_on_a_parameter_write() -> None:
    bench = Bench(1)
    codec = MitsubishiCodec()
    for exchange in codec.write(1, codec.parameter("Pr.8"), 0, 12.5, None):
        reply = codec.parse(exchange, bench.raw(exchange.request))
        assert reply.error is None
    (page, read) = codec.read(1, codec.parameter("Pr.8"), 0, None)
    codec.parse(page, bench.raw(page.request))
    value = codec.parse(read, bench.raw(read.request)).value
    assert value is not None
    assert (value.value, value.unit) == (12.5, "s")


def test_model_name_special_monitor_and_extended_status() -> None:
    bench = Bench(1)
    reply = decode_frame(bench.request(0x7C))
    assert isinstance(reply, DataReply)
    assert reply.text is not None
    assert reply.text.startswith("FR-E720")
    assert bench.write(0xF3, 0x08, 2) == Ack(1)  # DC bus voltage
    assert bench.read(0x72) == pytest.approx(5657, abs=5)  # 400 V mains peak, 0.1 V
    assert bench.write(0xF3, 0x04, 2) == nak(0xC)
    assert bench.read(0x79) == 0


# -- the communication check, trips and the reset -----------------------------------------


def test_communication_check_trips_with_e_pue_when_polls_stop() -> None:
    bench = Bench(1, parameters={"Pr.122": 1.0})
    bench.write(0xED, 5000)
    bench.write(0xFA, 0x02, 2)
    for _ in range(20):  # polled every 0.1 s: no trip
        bench.run_for(0.1)
        assert bench.read(0x7A) & ST.ABC1 == 0
    bench.run_for(1.5)  # the master went away
    status = bench.read(0x79)
    assert status & ST.FAULT
    assert status & ST.ABC1
    assert status & ST.RUN == 0  # output off
    assert bench.read(0x74) == 0x00B1  # latest E.PUE, no earlier fault


def test_pr122_zero_trips_as_soon_as_the_link_commands() -> None:
    bench = Bench(1, parameters={"Pr.122": 0.0})
    bench.write(0xED, 1000)
    assert bench.read(0x7A) & ST.ABC1 == 0
    bench.write(0xFA, 0x02, 2)
    assert bench.read(0x7A) & ST.ABC1


def test_reset_9696_gets_no_reply_and_the_drive_is_deaf_while_it_restarts() -> None:
    bench = Bench(1, parameters={"Pr.122": 0.5})
    bench.read(0x7A)
    bench.run_for(1.0)
    assert bench.read(0x7A) & ST.ABC1  # tripped on the check
    # FD 9696: 48+49+70+68+48+57+54+57+54 = 505 = 0x1F9
    assert bench.raw(b"\x0501FD09696F9\r") == b""
    assert bench.request(0x7A) == b""  # restarting
    bench.run_for(RESTART_S)
    assert bench.read(0x7A) == 0  # trip cleared, output off
    assert bench.read(0x74) == 0x00B1  # the history survives
    assert bench.write(0xF4, 0x9696) == Ack(1)
    assert bench.read(0x74) == 0


def test_reset_9966_acknowledges_first() -> None:
    bench = Bench(1)
    assert bench.write(0xFD, 0x9966) == Ack(1)
    assert bench.request(0x7A) == b""
    assert bench.request(0xFD, 0x1234, 4) == b""  # still deaf: no range error either


def test_a_reset_stops_a_running_motor() -> None:
    bench = Bench(1)
    bench.write(0xED, 5000)
    bench.write(0xFA, 0x02, 2)
    bench.run_for(6.0)
    bench.request(0xFD, 0x9696, 4)
    bench.run_for(RESTART_S)
    assert bench.read(0x7A) & ST.RUN == 0
    assert bench.read(0x6F) == 0


def test_drives_on_one_line_must_agree_on_the_line_settings() -> None:
    with pytest.raises(UsageError):
        build_line(
            LineSettings(protocol="mitsubishi"),
            [(1, DriveSettings()), (2, DriveSettings(parameters={"Pr.124": 2.0}))],
            clock=FakeClock(),
        )
