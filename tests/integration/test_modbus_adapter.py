"""The Modbus adapter over real sockets against a scripted gateway: outcomes, timing of the
answers, hostile and broken clients."""

from __future__ import annotations

import asyncio
import contextlib
import random
import struct
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Any

import pytest
from structlog.testing import capture_logs

from fcmaster.adapters.modbus import MAX_CONNECTIONS, REQUESTS_BURST, ModbusAdapter
from fcmaster.adapters.settings import ModbusSettings
from fcmaster.bus.commands import Action, Command, CommandResult, Outcome
from fcmaster.config import parse
from fcmaster.protocol.codec import DriveError
from tests.fakes import WallShiftedClock
from tests.integration.gateway_double import FakeGateway, Respond, done
from tests.integration.modbus_client import Client, ModbusError, f32
from tests.integration.mqtt_gateway import Gate

LIMIT_S = 20.0
HOST = "127.0.0.1"
CONFIG = """
buses:
  - name: line1
    port: sim://line1
    drives:
      - {name: pump-1, address: 1, control: bus, monitor: ["16-14"]}
      - {name: fan-1, address: 2, monitor: ["16-14"]}
modbus: {commands: true}
"""


@asynccontextmanager
async def serving(
    respond: Respond = done,
    *,
    commands: bool = True,
    wall: Callable[[], float] | None = None,
    partial_frame_s: float = 5.0,
    **options: Any,
) -> AsyncIterator[tuple[FakeGateway, ModbusAdapter]]:
    config = parse(CONFIG)
    clock = None if wall is None else WallShiftedClock(wall)
    gateway = FakeGateway(config.lines, respond, clock=clock)
    settings = ModbusSettings(listen="127.0.0.1:0", commands=commands, units=config.modbus_units())
    adapter = ModbusAdapter(
        settings, gateway, lines=config.lines, partial_frame_s=partial_frame_s, **options
    )
    async with asyncio.timeout(LIMIT_S), adapter:
        yield gateway, adapter


def result(outcome: Outcome) -> Respond:
    def respond(_drive: str, _command: Command) -> CommandResult:
        error = DriveError(2, "bad value") if outcome is Outcome.REFUSED else None
        return CommandResult(outcome=outcome, reason=f"scripted {outcome}", error=error)

    return respond


@pytest.mark.parametrize(
    ("outcome", "code"),
    [
        (Outcome.NOT_ALLOWED, 0x03),
        (Outcome.INVALID, 0x03),
        (Outcome.REFUSED, 0x04),
        (Outcome.TIMEOUT, 0x0B),
        (Outcome.CANCELLED, 0x0A),
    ],
    ids=lambda v: str(v),
)
async def test_each_outcome_answers_its_exception(outcome: Outcome, code: int) -> None:
    async with serving(result(outcome)) as (gateway, adapter), Client(*adapter.address) as client:
        with pytest.raises(ModbusError) as refused:
            await client.write_single(1, 0, 2)
        assert refused.value.code == code
        assert [(d, c.action) for d, c in gateway.executed] == [("pump-1", Action.STOP)]
        assert gateway.executed[0][1].actor.startswith("modbus:127.0.0.1:")


async def test_a_write_is_answered_once_its_command_ends_and_others_are_served_meanwhile() -> None:
    gate = Gate()
    async with (
        serving(gate) as (_, adapter),
        Client(*adapter.address) as writer,
        Client(*adapter.address) as reader,
    ):
        write = asyncio.create_task(writer.write_multiple(1, 0, [1, 2000]))
        drive, command = await gate.arrived.get()
        assert (drive, command.action, command.reference_pct) == ("pump-1", Action.START, 40.0)
        for _ in range(3):  # another client is answered while the start is out
            assert (await reader.read_input(1, 0, 1)) == [0]
        await asyncio.sleep(0.1)
        assert not write.done()
        gate.release("pump-1", "start")
        await write


async def test_writes_on_one_connection_are_carried_out_in_order() -> None:
    gate = Gate()
    async with serving(gate) as (gateway, adapter), Client(*adapter.address) as client:
        # Pipelined: a reference, then a start, sent before either is answered.
        reference = struct.pack(">HHHBBHH", 1, 0, 6, 1, 6, 1, 1500)
        start = struct.pack(">HHHBBHH", 2, 0, 6, 1, 6, 0, 1)
        await client.send_raw(reference + start)
        assert (await gate.arrived.get())[1].action is Action.SET_REFERENCE
        await asyncio.sleep(0.1)
        assert gate.arrived.empty()  # the start waits for the reference's outcome
        gate.release("pump-1", "set_reference")
        assert (await client.receive_frame())[0] == 1
        assert (await gate.arrived.get())[1].action is Action.START
        gate.release("pump-1", "start")
        assert (await client.receive_frame())[0] == 2
        assert [c.action for _, c in gateway.executed] == [Action.SET_REFERENCE, Action.START]


async def test_a_stop_with_a_reference_stops_first_then_sets_the_reference() -> None:
    async with serving() as (gateway, adapter), Client(*adapter.address) as client:
        await client.write_multiple(1, 0, [2, 1234])
        await client.write_multiple(1, 0, [0, 1000])  # 0: the reference only
        await client.write_single(1, 0, 0)  # nothing at all
    assert [(c.action, c.reference_pct) for _, c in gateway.executed] == [
        (Action.STOP, None),
        (Action.SET_REFERENCE, pytest.approx(24.68)),
        (Action.SET_REFERENCE, pytest.approx(20.0)),
    ]


async def test_commands_off_refuse_every_write_before_the_command_path() -> None:
    async with (
        serving(commands=False) as (gateway, adapter),
        Client(*adapter.address) as client,
    ):
        for write in (client.write_single(1, 0, 2), client.write_multiple(1, 0, [1, 100])):
            with pytest.raises(ModbusError) as refused:
                await write
            assert refused.value.code == 0x01
    assert gateway.executed == []


async def test_registers_follow_the_fleet_state_with_age_and_conditions() -> None:
    now = [0.0]
    async with (
        serving(wall=lambda: now[0]) as (gateway, adapter),
        Client(*adapter.address) as client,
    ):
        unknown = await client.read_input(1, 0, 20)
        assert unknown[:2] == [0, 0xFFFF]  # never answered: offline, age unknown
        gateway.reply(
            "pump-1", running=True, hz=42.5, value=("16-14", 12.3, "A"),
            alarms=((14, "Earth fault"), (9, "Inverter overloaded")),
            warnings=((12, "Torque limit"),),
        )  # fmt: skip
        state = gateway.fleet.get("line1", "pump-1")
        assert state is not None
        assert state.updated_at is not None
        now[0] = state.updated_at + 2.34
        words = await client.read_input(1, 0, 20)
        assert words[0:2] == [1, 23]  # online, 2.3 s old
        assert words[3:5] == [1, 1]  # running, fault
        assert words[8] == 4250  # 42.50 Hz
        assert words[10:14] == [14, 12, 2, 1]  # first alarm, first warning, their counts
        assert f32(words[16:18]) == pytest.approx(12.3)
        assert words[18:20] == [0, 123]  # the raw integer
        gateway.offline("pump-1")
        now[0] += 10.0
        words = await client.read_input(1, 0, 20)
        assert words[0:2] == [0, 123]
        assert words[8] == 0xFFFF


BROKEN = [
    pytest.param(bytes.fromhex("0001 0001 0006 01 04 0000 0001"), id="protocol-id-1"),
    pytest.param(bytes.fromhex("0001 0000 0000 01"), id="length-0"),
    pytest.param(bytes.fromhex("0001 0000 0001 01"), id="length-1-no-function"),
    pytest.param(bytes.fromhex("0001 0000 1000 01 04"), id="length-4096"),
    pytest.param(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n", id="http-request"),
]


@pytest.mark.parametrize("garbage", BROKEN)
async def test_a_header_that_is_not_modbus_closes_only_that_connection(garbage: bytes) -> None:
    with capture_logs() as logs:
        async with (
            serving() as (_, adapter),
            Client(*adapter.address) as bad,
            Client(*adapter.address) as good,
        ):
            await bad.send_raw(garbage)
            assert await bad.closed_by_server()
            assert (await good.read_input(1, 0, 1)) == [0]
    assert [e["event"] for e in logs if e["event"] == "modbus.frame_rejected"] == [
        "modbus.frame_rejected"
    ]
    assert not [e for e in logs if e["log_level"] == "error"]


REFUSED_PDUS = [
    pytest.param("2b 0e 01 00", 0x2B, 0x01, id="unsupported-function"),
    pytest.param("01 0000 0001", 0x01, 0x01, id="coils-are-not-served"),
    pytest.param("04 0000", 0x04, 0x03, id="read-truncated"),
    pytest.param("04 0000 0000", 0x04, 0x03, id="read-count-0"),
    pytest.param("04 0000 007e", 0x04, 0x03, id="read-count-126"),
    pytest.param("04 0000 0001 00", 0x04, 0x03, id="read-with-a-trailing-byte"),
    pytest.param("06 0000", 0x06, 0x03, id="write-single-truncated"),
    pytest.param("10 0000 0002 04 0001", 0x10, 0x03, id="write-multiple-short-of-its-bytes"),
    pytest.param("10 0000 0002 03 0001 00", 0x10, 0x03, id="write-multiple-count-mismatch"),
    pytest.param("03 0000 0003", 0x03, 0x02, id="read-beyond-the-holding-registers"),
    pytest.param("04 ffff 0002", 0x04, 0x02, id="read-address-wraps"),
]


@pytest.mark.parametrize(("pdu", "function", "code"), REFUSED_PDUS)
async def test_a_malformed_pdu_gets_its_exception_and_the_connection_goes_on(
    pdu: str, function: int, code: int
) -> None:
    async with serving() as (gateway, adapter), Client(*adapter.address) as client:
        body = bytes.fromhex(pdu)
        await client.send_raw(struct.pack(">HHHB", 77, 0, len(body) + 1, 1) + body)
        assert await client.receive_frame() == (77, 1, bytes((function | 0x80, code)))
        assert (await client.read_input(1, 0, 1)) == [0]  # the same connection still serves
    assert gateway.executed == []


async def test_silent_and_half_sending_clients_never_hold_up_the_others() -> None:
    with capture_logs() as logs:
        async with (
            serving(partial_frame_s=0.5) as (_, adapter),
            Client(*adapter.address) as silent,
            Client(*adapter.address) as halfway,
            Client(*adapter.address) as good,
        ):
            await halfway.send_raw(bytes.fromhex("0001 0000 0006 01 04"))  # 9 of 12 bytes
            loop = asyncio.get_running_loop()
            started = loop.time()
            for _ in range(20):
                assert (await good.read_input(1, 0, 1)) == [0]
            assert loop.time() - started < 5.0  # generous: the machine may be loaded
            assert await halfway.closed_by_server()  # the half frame was given 0.5 s
            assert (await silent.read_input(1, 0, 1)) == [0]  # an idle client keeps its place
    dropped = [e for e in logs if e["event"] == "modbus.client_dropped"]
    assert len(dropped) == 1


async def test_a_frame_split_into_single_bytes_is_still_one_request() -> None:
    async with serving() as (_, adapter), Client(*adapter.address) as client:
        frame = bytes.fromhex("0009 0000 0006 02 04 0000 0002")
        for byte in frame:
            await client.send_raw(bytes((byte,)))
            await asyncio.sleep(0.005)
        transaction, unit, pdu = await client.receive_frame()
        assert (transaction, unit, pdu[:2]) == (9, 2, bytes((4, 4)))


async def test_shutdown_ends_idle_clients_at_once_and_answers_a_pending_write_0x0a() -> None:
    gate = Gate()
    config = parse(CONFIG)
    settings = ModbusSettings(listen="127.0.0.1:0", commands=True, units=config.modbus_units())
    adapter = ModbusAdapter(settings, FakeGateway(config.lines, gate), lines=config.lines,
                            shutdown_grace_s=0.3)  # fmt: skip
    loop = asyncio.get_running_loop()
    async with asyncio.timeout(LIMIT_S):
        async with adapter:  # the clients outlive the server
            idle = await Client(*adapter.address).__aenter__()
            busy = await Client(*adapter.address).__aenter__()
            assert (await idle.read_input(1, 0, 1)) == [0]
            write = asyncio.create_task(busy.write_single(1, 0, 1))
            await gate.arrived.get()
            started = loop.time()
        assert 0.3 <= loop.time() - started < 2.0  # the grace, not forever
        with pytest.raises(ModbusError) as cancelled:
            await write
        assert cancelled.value.code == 0x0A
        assert await idle.closed_by_server()
        assert await busy.closed_by_server()
        for client in (idle, busy):
            await client.__aexit__(None, None, None)


async def test_an_idle_client_does_not_hold_up_shutdown() -> None:
    loop = asyncio.get_running_loop()
    async with asyncio.timeout(LIMIT_S), serving() as (_, adapter):
        client = await Client(*adapter.address).__aenter__()
        assert (await client.read_input(1, 0, 1)) == [0]
        started = loop.time()
    assert loop.time() - started < 1.0  # an idle connection is not waited for
    assert await client.closed_by_server()
    await client.__aexit__(None, None, None)


async def test_random_bytes_from_many_clients_never_take_the_server_down() -> None:
    rng = random.Random(20)
    header = bytes.fromhex("0001 0000 0006 01")

    def garbage() -> bytes:
        kind = rng.randrange(3)
        if kind == 0:  # anything at all
            return rng.randbytes(rng.randrange(1, 300))
        if kind == 1:  # a good header, a random PDU of the length it announces
            pdu = rng.randbytes(rng.randrange(1, 253))
            return struct.pack(">HHHB", rng.randrange(65536), 0, len(pdu) + 1, 1) + pdu
        return header + rng.randbytes(rng.randrange(0, 5))  # cut short

    with capture_logs() as logs:
        async with serving(partial_frame_s=0.3) as (gateway, adapter):

            async def hostile() -> None:
                async with Client(*adapter.address, timeout_s=5.0) as client:
                    for _ in range(5):
                        await client.send_raw(garbage())
                    with contextlib.suppress(ConnectionError, asyncio.IncompleteReadError):
                        await client.closed_by_server()  # answers, then EOF, or a reset

            await asyncio.gather(*(hostile() for _ in range(40)))
            async with Client(*adapter.address) as good:
                assert (await good.read_input(1, 0, 1)) == [0]
    assert not [e for e in logs if e["log_level"] in ("error", "critical")]
    assert all(command.actor.startswith("modbus:") for _, command in gateway.executed)


async def test_shutdown_lets_a_write_finish_within_the_grace_and_answers_it() -> None:
    gate = Gate()
    config = parse(CONFIG)
    settings = ModbusSettings(listen="127.0.0.1:0", commands=True, units=config.modbus_units())
    adapter = ModbusAdapter(settings, FakeGateway(config.lines, gate), lines=config.lines,
                            shutdown_grace_s=10.0)  # fmt: skip
    loop = asyncio.get_running_loop()
    async with asyncio.timeout(LIMIT_S):
        async with adapter:
            busy = await Client(*adapter.address).__aenter__()
            write = asyncio.create_task(busy.write_single(1, 0, 2))
            await gate.arrived.get()
            loop.call_later(0.2, gate.release, "pump-1", "stop")
            started = loop.time()
        assert loop.time() - started < 5.0  # the write's end, not the 10 s grace
        await write  # answered normally
        assert await busy.closed_by_server()
        await busy.__aexit__(None, None, None)


@pytest.mark.parametrize(
    ("code", "action"),
    [
        (1, Action.START),
        (2, Action.STOP),
        (3, Action.COAST),
        (4, Action.QUICK_STOP),
        (5, Action.RESET),
        (6, Action.FORWARD),
        (7, Action.REVERSE),
        (8, Action.JOG),
    ],
)
async def test_each_action_code_is_the_action_design_names(code: int, action: Action) -> None:
    async with serving() as (gateway, adapter), Client(*adapter.address) as client:
        await client.write_single(1, 0, code)
    assert [(d, c.action) for d, c in gateway.executed] == [("pump-1", action)]


async def test_a_full_server_lets_a_plc_in_in_the_place_of_the_oldest_idle_connection() -> None:
    async with serving() as (_, adapter), contextlib.AsyncExitStack() as stack:
        silent = [
            await stack.enter_async_context(Client(*adapter.address, timeout_s=5.0))
            for _ in range(MAX_CONNECTIONS)
        ]
        await asyncio.sleep(0.1)  # every one of them is being served, and idle
        async with Client(*adapter.address) as plc:
            assert (await plc.read_input(1, 0, 1)) == [0]
            assert await silent[0].closed_by_server()  # the one idle longest made room
            assert (await silent[1].read_input(1, 0, 1)) == [0]  # the others keep theirs
            assert adapter.evicted == 1
            async with Client(*adapter.address) as second:  # and again, the next oldest
                assert (await second.read_input(2, 0, 1)) == [0]
                assert await silent[2].closed_by_server()
            assert (await plc.read_input(1, 0, 1)) == [0]


async def test_a_frame_sent_a_byte_now_and_then_is_dropped() -> None:
    with capture_logs() as logs:
        async with (
            serving(partial_frame_s=0.5) as (_, adapter),
            Client(*adapter.address, timeout_s=5.0) as trickle,
        ):
            frame = bytes.fromhex("0009 0000 0006 01 04 0000 0001")
            with contextlib.suppress(ConnectionError):
                for byte in frame:  # each gap shorter than the 0.5 s, all together longer
                    await trickle.send_raw(bytes((byte,)))
                    await asyncio.sleep(0.2)
            assert await trickle.closed_by_server()  # not answered: dropped on the way
    reasons = [e["reason"] for e in logs if e["event"] == "modbus.client_dropped"]
    assert reasons == ["a frame not whole 0.5 s after its first byte"]


async def test_a_connection_that_sends_nothing_is_closed_after_the_idle_timeout() -> None:
    async with (
        serving(idle_timeout_s=0.5) as (_, adapter),
        Client(*adapter.address, timeout_s=5.0) as silent,
        Client(*adapter.address) as polling,
    ):
        for _ in range(6):  # a PLC polling every 0.2 s keeps its connection
            assert (await polling.read_input(1, 0, 1)) == [0]
            await asyncio.sleep(0.2)
        assert await silent.closed_by_server()
        assert (await polling.read_input(1, 0, 1)) == [0]


async def test_a_read_flood_is_answered_within_the_server_s_budget() -> None:
    async with serving(requests_per_s=100.0) as (_, adapter):

        async def flood() -> list[int]:
            async with Client(*adapter.address) as client:
                return [(await client.read_input(1, 0, 1))[0] for _ in range(REQUESTS_BURST)]

        answers = await asyncio.gather(flood(), flood())
        assert list(answers) == [[0] * REQUESTS_BURST] * 2  # every read answered, and rightly
        assert adapter.budget.waited >= REQUESTS_BURST - 10  # beyond the burst, paced
