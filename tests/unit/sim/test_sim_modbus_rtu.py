"""Simulated Modbus RTU drives: each enforces its profile's state machine, as the real one.

A run word out of sequence is ignored (the drive answers the write, and does not run);
the right sequence runs it; the status word says where it stands, in the profile's bits.
"""

from __future__ import annotations

import pytest

from fcmaster.protocol.modbus_rtu import (
    ExceptionReply,
    Function,
    ReadRequest,
    Registers,
    WriteSingle,
    decode_response,
    encode_request,
)
from fcmaster.protocol.modbus_rtu.profiles import BUILT_IN
from fcmaster.sim.modbus_rtu import ModbusSimDrive, State
from fcmaster.sim.settings import DriveSettings


def drive(profile: str) -> ModbusSimDrive:
    return ModbusSimDrive(1, DriveSettings(profile=profile), now=0.0)


def state(sim: ModbusSimDrive) -> State:
    return sim.machine.state


def write(sim: ModbusSimDrive, register: int, value: int, now: float = 0.1) -> object:
    answer = sim.handle(encode_request(WriteSingle(address=1, register=register, value=value)), now)
    assert answer is not None
    return decode_response(answer)


def read(sim: ModbusSimDrive, start: int, count: int = 1) -> tuple[int, ...]:
    request = ReadRequest(address=1, function=Function.READ_HOLDING, start=start, count=count)
    answer = sim.handle(encode_request(request), 0.2)
    assert answer is not None
    response = decode_response(answer)
    assert isinstance(response, Registers)
    return response.values


@pytest.mark.parametrize(
    ("profile", "control", "run_word"),
    [("altivar-cia402", 8501, 0x000F), ("abb-drives", 0, 0x047F), ("sinamics-v20", 99, 0x047F)],
)
def test_a_run_word_out_of_sequence_is_ignored(profile: str, control: int, run_word: int) -> None:
    sim = drive(profile)
    assert write(sim, control, run_word) == WriteSingle(address=1, register=control, value=run_word)
    assert state(sim) is State.SWITCH_ON_DISABLED
    assert not sim.machine.running
    for word in BUILT_IN[profile].commands["start"]:
        write(sim, control, word)
    assert state(sim) is State.OPERATION_ENABLED
    assert sim.machine.running


def test_cia402_status_words_follow_the_states() -> None:
    sim = drive("altivar-cia402")
    words = []
    for word in (0x06, 0x07, 0x0F):
        write(sim, 8501, word)
        words.append(read(sim, 3201)[0] & 0x6F)
    assert words == [0x21, 0x23, 0x27]
    write(sim, 8501, 0x0000)  # disable voltage: coast
    assert read(sim, 3201)[0] & 0x4F == 0x40


def test_abb_words_need_the_remote_bit() -> None:
    sim = drive("abb-drives")
    write(sim, 0, 0x007E)  # bit 10 clear: not a fieldbus command
    write(sim, 0, 0x007F)
    assert not sim.machine.running


def test_a_tripped_drive_ignores_run_words_until_reset_after_its_cause() -> None:
    sim = drive("yaskawa-memobus")
    sim.raise_fault(7, 0.05)
    write(sim, 1, 0x0001)
    assert not sim.machine.running
    assert read(sim, 0x0080) == (7,)
    write(sim, 1, 0x0008)  # reset while the cause is there: still tripped
    assert state(sim) is State.FAULT
    write(sim, 1, 0x0000)
    sim.clear_fault(0.15)
    write(sim, 1, 0x0008)
    assert state(sim) is not State.FAULT
    write(sim, 1, 0x0001)
    assert sim.machine.running


def test_unknown_registers_are_refused_and_a_bad_crc_unanswered() -> None:
    sim = drive("abb-drives")
    request = encode_request(
        ReadRequest(address=1, function=Function.READ_HOLDING, start=9999, count=1)
    )
    answer = sim.handle(request, 0.1)
    assert answer is not None
    assert decode_response(answer) == ExceptionReply(address=1, function=3, code=2)
    assert sim.handle(request[:-1] + bytes((request[-1] ^ 0xFF,)), 0.1) is None
    assert sim.handle(encode_request(WriteSingle(address=2, register=0, value=1)), 0.1) is None


def test_a_broadcast_write_is_obeyed_and_not_answered() -> None:
    sim = drive("danfoss-fc-modbus")
    assert (
        sim.handle(encode_request(WriteSingle(address=0, register=49999, value=0x047C)), 0.1)
        is None
    )
    assert sim.machine.running


def test_without_a_named_profile_the_built_ins_take_turns_by_address() -> None:
    names = [ModbusSimDrive(a, now=0.0).profile.name for a in range(1, 7)]
    assert names == [*BUILT_IN, "abb-drives"]


@pytest.mark.parametrize(
    ("profile", "watchdog", "fault"),
    [
        ("abb-drives", {"hr5815": 10, "hr5813": 1}, 6681),
        ("altivar-cia402", {"hr6005": 10, "hr7002": 1}, 5),
        ("sinamics-v20", {"hr0": 1000}, 72),
    ],
)
def test_the_drives_watchdog_trips_it_when_the_master_falls_silent(
    profile: str, watchdog: dict[str, float], fault: int
) -> None:
    sim = ModbusSimDrive(1, DriveSettings(profile=profile, parameters=watchdog), now=0.0)
    control = BUILT_IN[profile].control.address
    for word in BUILT_IN[profile].commands["start"]:
        write(sim, control, word, now=0.1)
    write(sim, control, BUILT_IN[profile].commands["start"][-1], now=0.9)  # in time: fed
    assert sim.machine.running
    write(sim, control, BUILT_IN[profile].commands["start"][-1], now=2.5)  # 1.6 s of silence
    assert state(sim) is State.FAULT
    assert sim.machine.fault == fault
    assert not sim.machine.running


def test_an_unsigned_frequency_register_shows_the_magnitude_of_a_reverse_run() -> None:
    sim = drive("yaskawa-memobus")  # output frequency 0x0024: unsigned 0.01 Hz
    write(sim, 0x0002, 2000)  # 20 Hz
    write(sim, 0x0001, 0x0002)  # reverse run
    request = ReadRequest(address=1, function=Function.READ_HOLDING, start=0x0024, count=1)
    answer = sim.handle(encode_request(request), 5.0)
    assert sim.motor.frequency_hz == pytest.approx(-20.0)
    assert answer is not None
    assert decode_response(answer) == Registers(
        address=1, function=Function.READ_HOLDING, values=(2000,)
    )
