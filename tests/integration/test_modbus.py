"""The Modbus TCP server in the real daemon over simulated lines, through real sockets.

The client here is written from the specification (tests/integration/modbus_client.py);
``mbpoll``, a C client from Debian, checks the same server in test_modbus_mbpoll.py.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from structlog.testing import capture_logs

from fcmaster import config
from fcmaster.clock import MonotonicClock
from fcmaster.service import Service
from tests.fakes import WallShiftedClock
from tests.integration.modbus_client import Client, ModbusError, f32, i32, is_nan
from tests.integration.modbus_harness import Plant, plant
from tests.integration.ports import free_port
from tests.integration.waiting import wait_for

LIMIT_S = 30.0
HOST = "127.0.0.1"


async def registers_settle(client: Client, unit: int, check: object) -> list[int]:
    """Read unit's input registers 0-31 until ``check(words)`` holds."""
    assert callable(check)
    async with asyncio.timeout(10):
        while True:
            words = await client.read_input(unit, 0, 32)
            if check(words):
                return words
            await asyncio.sleep(0.05)


def values_read(plant: Plant) -> bool:
    state = plant.service.fleet.get("line1", "pump-1")
    return state is not None and {"16-13", "16-14", "16-30", "16-90"} <= set(state.values)


async def test_register_ages_are_told_by_the_daemons_clock() -> None:
    # A wall clock 25 years behind the machine's: had the adapter read the machine's own,
    # every age would be beyond its range (the unknown mark, 0xFFFF).
    clock: MonotonicClock = WallShiftedClock(lambda: 1_000_000_000.0 + clock.now())
    async with (
        asyncio.timeout(LIMIT_S),
        plant(clock=clock) as running,
        Client(HOST, running.port) as client,
    ):
        await running.service.hub.wait_for(lambda: values_read(running), timeout_s=10)
        state = running.service.fleet.get("line1", "pump-1")
        assert state is not None
        assert state.updated_at is not None
        assert abs(state.updated_at - clock.wall()) < 5.0  # the fleet stamps with it too
        words = await client.read_input(1, 0, 2)
        assert words[0] == 1  # online
        assert words[1] < 20  # age_s in 0.1 s: polled moments ago


async def test_input_registers_show_the_simulated_drives() -> None:
    async with asyncio.timeout(LIMIT_S), plant() as running, Client(HOST, running.port) as client:
        await running.service.hub.wait_for(lambda: values_read(running), timeout_s=10)
        words = await client.read_input(1, 0, 32)
        drive = running.drive("line1", 1)
        assert words[0] == 1  # online
        assert words[1] < 20  # age_s in 0.1 s: polled moments ago
        assert words[2] == drive.control.status_word
        assert words[3:6] == [0, 0, 0]  # not running, no fault, no warning
        assert words[8] == 0  # stopped: 0.00 Hz
        assert words[10:14] == [0, 0, 0, 0]  # no alarm, no warning
        assert words[14:16] == [0, 0]  # reserved
        # 16-30 (DC link, the third monitored value) at 24-27: the value and the raw integer
        assert f32(words[24:26]) == pytest.approx(drive.motor.dc_link_v, abs=1.0)
        assert i32(words[26:28]) == round(drive.motor.dc_link_v)
        with pytest.raises(ModbusError) as beyond:  # four monitored values end at 31
            await client.read_input(1, 30, 3)
        assert beyond.value.code == 0x02
        assert f32(words[16:18]) == 0.0  # 16-13 frequency
        # Unit 11 is line2's drive at address 1 (modbus_unit), not line1's.
        other = await client.read_input(11, 0, 3)
        assert other == [1, other[1], running.drive("line2", 1).control.status_word]
        holding = await client.read_holding(1, 0, 2)
        assert holding[0] == 0  # command reads 0


async def test_a_start_with_a_reference_reaches_the_simulated_drive() -> None:
    with capture_logs() as logs:
        async with (
            asyncio.timeout(LIMIT_S),
            plant() as running,
            Client(HOST, running.port) as client,
        ):
            drive = running.drive("line1", 1)
            await client.write_multiple(1, 0, [1, 2500])  # start at 25.00 Hz
            # Answered once done: the drive already has the reference and the run command.
            assert drive.control.reference_pct == pytest.approx(50.0, abs=0.01)  # of 50 Hz nominal
            words = await registers_settle(client, 1, lambda w: w[3] == 1 and w[8] > 500)
            assert words[9] == 5000  # reference_pct 50.00 %
            assert 0 < f32(words[16:18]) <= 25.0  # 16-13 read from the drive
            assert (await client.read_holding(1, 1, 1)) == [2500]  # reference_hz

            await client.write_single(1, 1, 3000)  # 30.00 Hz
            assert drive.control.reference_pct == pytest.approx(
                60.0, abs=0.01
            )  # FC: 0x4000 = 100 %
            await client.write_single(1, 0, 2)  # stop
            await wait_for(lambda: drive.motor.frequency_hz == 0.0)
    port = f"modbus:{HOST}:"
    audit = [
        (e["actor"].startswith(port), e["drive"], e["command"], e["outcome"])
        for e in logs
        if e["event"] == "command.completed"
    ]
    assert audit == [
        (True, "pump-1", "start", "done"),
        (True, "pump-1", "set_reference", "done"),
        (True, "pump-1", "stop", "done"),
    ]


REFUSALS = [
    pytest.param(1, 1, [5000], 0x03, id="reference-beyond-the-limit"),
    pytest.param(1, 0, [1, 4500], 0x03, id="start-beyond-the-limit"),
    pytest.param(2, 0, [1], 0x03, id="monitor-only-drive"),
    pytest.param(1, 0, [9], 0x03, id="no-such-action-code"),
    pytest.param(1, 1, [1, 2], 0x02, id="beyond-the-holding-registers"),
    pytest.param(7, 0, [1], 0x0A, id="no-such-unit"),
]


@pytest.mark.parametrize(("unit", "address", "values", "code"), REFUSALS)
async def test_a_refused_write_answers_its_exception_and_puts_nothing_on_the_wire(
    unit: int, address: int, values: list[int], code: int
) -> None:
    async with asyncio.timeout(LIMIT_S), plant() as running, Client(HOST, running.port) as client:
        before = {a: running.control_sent("line1", a) for a in (1, 2)}
        mark = running.frames("line1")
        write = (
            client.write_single(unit, address, values[0])
            if len(values) == 1
            else client.write_multiple(unit, address, values)
        )
        with pytest.raises(ModbusError) as refused:
            await write
        assert refused.value.code == code
        await wait_for(lambda: running.frames("line1") > mark + 10)  # polls went on
        for a in (1, 2):  # each drive got only the control words and references it got before
            assert running.control_sent("line1", a, since=mark) <= before[a]
        drive = running.drive("line1", 1)
        assert (drive.motor.frequency_hz, drive.control.reference_pct) == (0.0, 0.0)


async def test_read_only_by_default_answers_writes_illegal_function() -> None:
    with capture_logs() as logs:
        async with (
            asyncio.timeout(LIMIT_S),
            plant("{listen: 127.0.0.1:PORT}") as running,
            Client(HOST, running.port) as client,
        ):
            mark = running.frames("line1")
            before = running.control_sent("line1", 1)
            for write in (client.write_single(1, 0, 1), client.write_multiple(1, 0, [1, 2000])):
                with pytest.raises(ModbusError) as refused:
                    await write
                assert refused.value.code == 0x01
            assert (await client.read_input(1, 0, 1)) == [1]  # reads still served
            await wait_for(lambda: running.frames("line1") > mark + 10)
            assert running.control_sent("line1", 1, since=mark) <= before
            assert running.drive("line1", 1).control.reference_pct == 0.0
    refusals = [e for e in logs if e["event"] == "modbus.command_refused"]
    assert len(refusals) == 2
    assert "read-only" in refusals[0]["reason"]
    assert not [e for e in logs if e["event"] == "command.completed"]


async def test_an_address_outside_the_allow_list_is_closed_unanswered() -> None:
    async with (
        asyncio.timeout(LIMIT_S),
        plant("{listen: 127.0.0.1:PORT, allow: [192.0.2.0/24]}") as running,
        Client(HOST, running.port) as client,
    ):
        await client.send_raw(bytes.fromhex("0001 0000 0006 01 04 0000 0001"))
        assert await client.closed_by_server()
    async with (
        asyncio.timeout(LIMIT_S),
        plant("{listen: 127.0.0.1:PORT, allow: [127.0.0.1]}") as running,
        Client(HOST, running.port) as client,
    ):
        assert (await client.read_input(1, 0, 1)) == [1]


async def test_an_offline_drive_reads_online_0_its_age_and_unknown_values() -> None:
    silent = "{drives: {1: {faults: silent_at=3-300}}}"  # pump-3 stops answering after 3 s
    async with (
        asyncio.timeout(LIMIT_S),
        plant(line2=silent) as running,
        Client(HOST, running.port) as client,
    ):
        fresh = await client.read_input(11, 0, 20)
        assert fresh[0] == 1
        assert fresh[2] != 0xFFFF
        assert not is_nan(fresh[16:18])
        state = running.service.fleet.get("line2", "pump-3")
        await running.service.hub.wait_for(
            lambda: not running.online("line2", "pump-3"), timeout_s=15
        )
        words = await client.read_input(11, 0, 20)
        assert words[0] == 0
        assert 0 < words[1] < 600  # tenths of a second since the last good reply
        assert words[2:14] == [0xFFFF] * 12
        assert is_nan(words[16:18])
        assert words[18:20] == [0x8000, 0]
        assert (await client.read_holding(11, 1, 1)) == [0xFFFF]
        assert state is not None
        assert state.online  # the snapshot read before stays as it was: immutable


async def test_a_silent_drive_answers_0x0b_and_a_line_that_is_down_0x0a() -> None:
    silent = "{drives: {1: {faults: silent_at=3-300}}}"
    async with (
        asyncio.timeout(LIMIT_S),
        plant(line2=silent) as running,
        Client(HOST, running.port) as client,
    ):
        await running.service.hub.wait_for(
            lambda: not running.online("line2", "pump-3"), timeout_s=15
        )
        with pytest.raises(ModbusError) as no_answer:
            await client.write_single(11, 0, 2)  # stop: tried, retried, no answer
        assert no_answer.value.code == 0x0B


async def test_a_write_to_a_drive_on_a_line_that_is_down_answers_0x0a(tmp_path: Path) -> None:
    port = free_port()
    text = f"""
buses:
  - name: line1
    port: {tmp_path / "no-such-adapter"}
    drives: [{{name: pump-1, address: 1, control: bus}}]
modbus: {{listen: "127.0.0.1:{port}", commands: true}}
"""
    service = Service(config.parse(text))
    task = asyncio.create_task(service.run(install_signals=False))
    try:
        async with asyncio.timeout(LIMIT_S):
            while True:  # until the server listens (the line keeps failing to open)
                try:
                    client = await Client(HOST, port).__aenter__()
                    break
                except OSError:
                    await asyncio.sleep(0.05)
            words = await client.read_input(1, 0, 2)
            assert words == [0, 0xFFFF]  # never answered
            with pytest.raises(ModbusError) as down:
                await client.write_single(1, 0, 1)
            assert down.value.code == 0x0A
            await client.__aexit__(None, None, None)
    finally:
        service.stop()
        await task
