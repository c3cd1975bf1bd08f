"""The doctor's probing in virtual time, against scripted lines: what it takes for an echo,
a reply, a collision or noise, and the order it tries settings in."""

from __future__ import annotations

import itertools
from collections.abc import Callable

import pytest

from fcmaster.bus.plan import LinePlan
from fcmaster.errors import PortError, UsageError
from fcmaster.protocol.danfoss_fc import AddressFormat, Telegram, encode_telegram
from fcmaster.subcommands.diagnosis import Survey, diagnose, to_text
from fcmaster.subcommands.doctor import examine
from fcmaster.transport.pipe import Transport
from fcmaster.transport.usb import Adapter
from tests.fakes import Responder, ScriptedTransport, Timed, VirtualClock

READY = 0x0607


def reply(address: int, address_format: AddressFormat = AddressFormat.FORMAT_126) -> bytes:
    return encode_telegram(Telegram(address=address, address_format=address_format,
                                    pcd1=READY, pcd2=0))  # fmt: skip


def adr(request: bytes) -> int:
    return request[2] & 0x7F if request[2] & 0x80 else request[2]


def at(baudrate: int, parity: str, drives: Callable[[bytes], bytes | Timed | None]) -> Callable[
    [LinePlan], Responder
]:  # fmt: skip
    """Drives that answer only a master at ``baudrate`` and ``parity``."""

    def responder_for(plan: LinePlan) -> Responder:
        if (plan.baudrate, plan.parity) == (baudrate, parity):
            return drives
        return lambda request: None

    return responder_for


async def doctor(
    responder_for: Callable[[LinePlan], Responder],
    *,
    addresses: list[int] | None = None,
    fail_at: frozenset[int] = frozenset(),
    transports: list[ScriptedTransport] | None = None,
) -> tuple[Survey, list[tuple[int, str]]]:
    clock = VirtualClock()
    opened: list[tuple[int, str]] = []

    def open_transport(plan: LinePlan) -> Transport:
        opened.append((plan.baudrate, plan.parity))
        transport = ScriptedTransport(clock, responder_for(plan), char_s=plan.char_s)
        transport.fail_open = plan.baudrate in fail_at
        if transports is not None:
            transports.append(transport)
        return transport

    survey = await clock.complete(
        examine("/dev/ttyUSB0", protocols=("danfoss-fc",), addresses=addresses or [1, 2, 3],
                open_transport=open_transport, clock=clock),
        within=600.0,
    )  # fmt: skip
    return survey, opened


def drives_at(*present: int) -> Responder:
    return lambda request: reply(adr(request)) if adr(request) in present else None


async def test_settings_are_tried_fastest_first_with_the_factory_parity_first() -> None:
    survey, opened = await doctor(at(9600, "O", drives_at(2)))
    rates = (115200, 76800, 57600, 38400, 19200)
    assert opened == [(r, p) for r in rates for p in "EON"] + [(9600, "E"), (9600, "O")]
    assert survey.found is not None
    assert (survey.found.baudrate, survey.found.parity) == (9600, "O")
    assert survey.drives == [2]
    assert survey.settings_tried == 17
    [report] = survey.addresses
    assert (report.attempts, report.answered) == (3, 3)


async def test_an_echo_in_pieces_is_taken_off_and_the_reply_behind_it_read() -> None:
    def echoing(request: bytes) -> Timed | None:
        pieces = [(0.001, request[:3]), (0.004, request[3:])]
        if adr(request) == 1:
            pieces.append((0.020, reply(1)))
        return Timed(tuple(pieces))

    survey, _ = await doctor(at(115200, "E", echoing))
    assert survey.drives == [1]
    assert survey.echoes == survey.requests
    assert survey.noise_bytes == 0


async def test_a_reply_that_starts_like_the_request_is_no_echo() -> None:
    # An FC reply begins STX, LGE, ADR like its request: byte by byte, it is still a reply.
    def bytewise(request: bytes) -> Timed | None:
        if adr(request) != 1:
            return None
        return Timed(tuple((0.010 + i * 0.001, bytes([b])) for i, b in enumerate(reply(1))))

    survey, _ = await doctor(at(115200, "E", bytewise))
    assert survey.echoes == 0
    assert survey.drives == [1]
    assert survey.addresses[0].answered == 3


async def test_two_replies_to_one_request_are_doubled_and_garbage_is_garbled() -> None:
    def twins(request: bytes) -> Timed | None:
        if adr(request) == 1:  # one answers at 10 ms, the other at 25 ms
            return Timed(((0.010, reply(1)), (0.025, reply(1))))
        if adr(request) == 2:  # both at once: a reply's worth and more that never checks
            return Timed(((0.012, bytes(b ^ 0x5A for b in reply(2) * 2)),))
        if adr(request) == 3:
            return Timed(((0.010, reply(3)),))
        return None

    survey, _ = await doctor(at(115200, "E", twins))
    reports = {r.address: r for r in survey.addresses}
    assert (reports[1].doubled, reports[1].answered, reports[1].collides) == (3, 0, True)
    assert (reports[2].garbled, reports[2].answered, reports[2].collides) == (3, 0, True)
    assert (reports[3].answered, reports[3].collides) == (3, False)
    assert survey.drives == [1, 2, 3]
    assert survey.noise_bytes == 0  # collision garbage is not noise


async def test_noise_before_a_reply_is_counted_and_the_reply_still_read() -> None:
    def noisy(request: bytes) -> Timed:
        pieces = [(0.003, b"\x55\xaa\x13")]
        if adr(request) == 1:
            pieces.append((0.015, reply(1)))
        return Timed(tuple(pieces))

    survey, _ = await doctor(at(115200, "E", noisy))
    assert survey.drives == [1]
    # 3 bytes after every request: 1 probe at 115200 8E1, then 3 attempts at address 1 and
    # one at each of 2 and 3.
    assert survey.requests == 6
    assert survey.noise_bytes == 3 * 6


async def test_drives_that_answer_only_the_31_address_format() -> None:
    def old_drives(request: bytes) -> bytes | None:
        if request[2] & 0x80 or request[2] != 1:
            return None
        return reply(1, AddressFormat.FORMAT_31)

    survey, _ = await doctor(at(115200, "E", old_drives))
    assert survey.only_options == (("address_format", 31),)
    assert survey.found is not None
    assert survey.found.value("address_format") == 31
    assert survey.drives == [1]


async def test_timing_of_the_reply_is_measured_without_the_wire() -> None:
    survey, _ = await doctor(at(115200, "E", drives_at(1)))
    # ScriptedTransport delivers 10 ms after both frames' wire time.
    assert survey.turnaround_ms == pytest.approx(10.0, abs=0.01)


async def test_rates_the_port_refuses_are_skipped_and_a_port_that_never_opens_fails() -> None:
    survey, opened = await doctor(at(57600, "E", drives_at(1)), fail_at=frozenset({76800}))
    assert survey.found is not None
    assert survey.found.baudrate == 57600
    assert (76800, "E") in opened
    with pytest.raises(PortError):
        await doctor(at(57600, "E", drives_at(1)), fail_at=frozenset({115200, 76800, 57600,
                     38400, 19200, 9600, 4800, 2400}))  # fmt: skip


async def test_an_address_no_protocol_reaches_is_refused_before_the_port_opens() -> None:
    with pytest.raises(UsageError, match="address 200 is outside every protocol's range"):
        await doctor(at(9600, "E", drives_at(1)), addresses=[1, 200])


async def test_a_socket_converter_is_tried_once_per_protocol_at_its_own_settings() -> None:
    # The converter's serial side is set on the converter: the port takes no baud rate, so
    # drives that answer "at every rate" must not be reported at the first one tried.
    clock = VirtualClock()
    opened: list[tuple[int, str]] = []

    def open_transport(plan: LinePlan) -> Transport:
        opened.append((plan.baudrate, plan.parity))
        return ScriptedTransport(clock, drives_at(1), char_s=plan.char_s)

    survey = await clock.complete(
        examine("socket://10.0.0.7:4001", protocols=("danfoss-fc",), addresses=[1, 2],
                open_transport=open_transport, clock=clock),
    )  # fmt: skip
    assert opened == [(9600, "E")]  # the factory settings, once
    assert not survey.settings_probed
    assert survey.drives == [1]
    assert diagnose(survey) == []
    assert "line      danfoss-fc (the converter's own serial settings)" in to_text(survey, [])


async def test_a_reply_at_the_end_of_its_window_still_gets_the_protocols_pause() -> None:
    char_s = 11 / 115200
    window = 16 * char_s + 0.010 + 0.030  # request and reply on the wire, 8-35, the margin
    late = window - 0.0001  # the last moment a reply is still taken
    lines: list[ScriptedTransport] = []
    survey, _ = await doctor(
        at(115200, "E", lambda r: Timed(((late, reply(adr(r))),))), transports=lines
    )
    assert survey.drives == [1, 2, 3]
    sent = lines[0].sent
    assert len(sent) == 1 + 3 * 3  # the probe, then three attempts at each address
    for previous, following in itertools.pairwise(sent):
        assert previous.reply_at is not None
        assert following.at - previous.reply_at >= 2 * char_s - 1e-9  # FC: two characters


async def test_the_adapter_the_port_opened_on_is_kept_for_the_diagnosis() -> None:
    # SerialTransport describes the USB adapter behind a local port once it is open (its
    # latency timer read back after asking for 1 ms); the doctor reports what it found.
    clock = VirtualClock()
    ftdi = Adapter(device="/dev/ttyUSB0", driver="ftdi_sio", by_id=None, by_path=None,
                   latency_ms=16)  # fmt: skip

    def open_transport(plan: LinePlan) -> Transport:
        transport = ScriptedTransport(clock, at(19200, "E", drives_at(1))(plan), char_s=plan.char_s)
        transport.adapter = ftdi
        return transport

    survey = await clock.complete(
        examine("/dev/ttyUSB0", protocols=("danfoss-fc",), addresses=[1],
                open_transport=open_transport, clock=clock),
    )  # fmt: skip
    assert survey.adapter is ftdi
    assert [f.code for f in diagnose(survey)] == ["adapter_latency"]
