"""FC profile: control words from protocols/danfoss-fc.md §8.3, status bits §8.4, reference §8.5."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fcmaster.errors import UsageError
from fcmaster.protocol.danfoss_fc import (
    IGNORED_CONTROL_WORD,
    ControlWord,
    StatusWord,
    control_word,
    decode_reference,
    encode_reference,
)
from fcmaster.protocol.danfoss_fc.profile import executed_motion, flag_names
from fcmaster.protocol.drive import ControlIntent, Motion

# ---------------------------------------------------------------- control word (§8.1, §8.3)


@pytest.mark.parametrize(
    ("intent", "ctw"),
    [
        pytest.param(ControlIntent(Motion.RUN), 0x047C, id="start-0x047C"),
        pytest.param(ControlIntent(Motion.STOP), 0x043C, id="ramp-stop-0x043C"),
        pytest.param(ControlIntent(Motion.COAST), 0x0474, id="coast-0x0474"),
        pytest.param(ControlIntent(Motion.QUICK_STOP), 0x046C, id="quick-stop-0x046C"),
        pytest.param(ControlIntent(Motion.RUN, reset=True), 0x04FC, id="reset-0x04FC"),
        pytest.param(ControlIntent(Motion.JOG), 0x057C, id="jog-0x057C"),
        pytest.param(ControlIntent(Motion.RUN, reverse=True), 0x847C, id="reverse-0x847C"),
    ],
)
def test_control_word_matches_the_manual_table(intent: ControlIntent, ctw: int) -> None:
    assert control_word(intent) == ctw


@pytest.mark.parametrize(
    ("bits", "ctw"),
    [
        pytest.param((2, 3, 4, 5, 6), 0x047C, id="start"),
        pytest.param((2, 3, 4, 5), 0x043C, id="ramp-stop"),
        pytest.param((2, 4, 5, 6), 0x0474, id="coast"),
        pytest.param((2, 3, 5, 6), 0x046C, id="quick-stop"),
        pytest.param((3, 4, 5, 6), 0x0478, id="dc-brake-stop"),
        pytest.param((2, 3, 4, 6), 0x045C, id="freeze"),
        pytest.param((2, 3, 4, 5, 6, 7), 0x04FC, id="reset"),
        pytest.param((2, 3, 4, 5, 6, 8), 0x057C, id="jog"),
        pytest.param((2, 3, 4, 5, 6, 9), 0x067C, id="ramp-2"),
        pytest.param((2, 3, 4, 5, 6, 15), 0x847C, id="reverse"),
    ],
)
def test_control_words_of_the_table_are_bit_10_plus_the_listed_bits(
    bits: tuple[int, ...], ctw: int
) -> None:
    assert sum(1 << bit for bit in bits) | 1 << 10 == ctw


@pytest.mark.parametrize(
    ("flag", "bit"),
    [
        (ControlWord.PRESET_REFERENCE_LSB, 0),
        (ControlWord.PRESET_REFERENCE_MSB, 1),
        (ControlWord.NO_DC_BRAKE, 2),
        (ControlWord.NO_COAST, 3),
        (ControlWord.NO_QUICK_STOP, 4),
        (ControlWord.NO_FREEZE, 5),
        (ControlWord.START, 6),
        (ControlWord.RESET, 7),
        (ControlWord.JOG, 8),
        (ControlWord.RAMP_2, 9),
        (ControlWord.DATA_VALID, 10),
        (ControlWord.RELAY_01, 11),
        (ControlWord.RELAY_02, 12),
        (ControlWord.SETUP_LSB, 13),
        (ControlWord.SETUP_MSB, 14),
        (ControlWord.REVERSE, 15),
    ],
    ids=lambda value: getattr(value, "name", str(value)),
)
def test_control_word_bits_are_where_the_manual_puts_them(flag: ControlWord, bit: int) -> None:
    assert flag == 1 << bit


def test_ignored_control_word_has_bit_10_clear() -> None:
    assert not IGNORED_CONTROL_WORD & 1 << 10


intents = st.builds(
    ControlIntent,
    motion=st.sampled_from(Motion),
    reverse=st.booleans(),
    reference_pct=st.floats(-200, 199.99),
    reset=st.booleans(),
)


@given(intents)
def test_every_control_word_is_valid_and_says_only_what_the_intent_asks(
    intent: ControlIntent,
) -> None:
    word = control_word(intent)
    assert 0 <= word <= 0xFFFF
    assert word & 1 << 10, "bit 10: the drive must act on a commanding word"
    assert word & 1 << 2, "never DC brake"
    assert word & 1 << 5, "never freeze"
    assert not word & (1 << 0 | 1 << 1 | 1 << 9 | 1 << 11 | 1 << 12 | 1 << 13 | 1 << 14)
    assert bool(word & 1 << 3) is (intent.motion is not Motion.COAST)
    assert bool(word & 1 << 4) is (intent.motion is not Motion.QUICK_STOP)
    assert bool(word & 1 << 6) is (intent.motion is not Motion.STOP)
    assert bool(word & 1 << 8) is (intent.motion is Motion.JOG)
    assert bool(word & 1 << 7) is intent.reset
    assert bool(word & 1 << 15) is intent.reverse


# ---------------------------------------------------------------- status word (§8.4)


@pytest.mark.parametrize(
    ("flag", "bit"),
    [
        (StatusWord.CONTROL_READY, 0),
        (StatusWord.DRIVE_READY, 1),
        (StatusWord.ENABLED, 2),
        (StatusWord.TRIP, 3),
        (StatusWord.ERROR, 4),
        (StatusWord.TRIP_LOCK, 6),
        (StatusWord.WARNING, 7),
        (StatusWord.AT_REFERENCE, 8),
        (StatusWord.BUS_CONTROL, 9),
        (StatusWord.FREQUENCY_OK, 10),
        (StatusWord.RUNNING, 11),
        (StatusWord.AUTO_RESTART_PENDING, 12),
        (StatusWord.VOLTAGE_EXCEEDED, 13),
        (StatusWord.TORQUE_EXCEEDED, 14),
        (StatusWord.TIMER_EXCEEDED, 15),
    ],
    ids=lambda value: getattr(value, "name", str(value)),
)
def test_status_word_bits_are_where_the_manual_puts_them(flag: StatusWord, bit: int) -> None:
    assert flag == 1 << bit


def test_flag_names_reads_a_running_drive_status() -> None:
    # 0x0F07: bits 0, 1, 2 (ready, enabled), 8, 9, 10, 11 (at reference, bus, limits OK, running)
    names = flag_names(0x0F07, StatusWord)
    active = {name for name, on in names.items() if on}
    assert active == {
        "control_ready", "drive_ready", "enabled", "at_reference", "bus_control",
        "frequency_ok", "running",
    }  # fmt: skip
    assert len(names) == 16


def test_flag_names_reads_the_start_word() -> None:
    active = {name for name, on in flag_names(0x047C, ControlWord).items() if on}
    expected = {"no_dc_brake", "no_coast", "no_quick_stop", "no_freeze", "start", "data_valid"}
    assert active == expected


# ---------------------------------------------------------------- reference (§8.5)


@pytest.mark.parametrize(
    ("percent", "raw"),
    [
        pytest.param(100.0, 0x4000, id="100pct-0x4000"),
        pytest.param(-100.0, 0xC000, id="minus-100pct-0xC000"),
        pytest.param(50.0, 0x2000, id="50pct-0x2000"),
        pytest.param(0.0, 0x0000, id="0pct"),
        pytest.param(-200.0, 0x8000, id="minus-200pct-0x8000"),
        pytest.param(25.0, 0x1000, id="25pct-0x1000"),
        pytest.param(-50.0, 0xE000, id="minus-50pct-0xE000"),
    ],
)
def test_reference_scaling_both_ways(percent: float, raw: int) -> None:
    assert encode_reference(percent) == raw
    assert decode_reference(raw) == percent


def test_reference_full_scale_top_is_0x7fff() -> None:
    top = 32767 * 100 / 16384  # 199.99389... %
    assert decode_reference(0x7FFF) == pytest.approx(top)
    assert encode_reference(top) == 0x7FFF
    assert decode_reference(0x0001) == pytest.approx(100 / 16384)  # resolution 2^-14


@pytest.mark.parametrize("percent", [200.0, 199.995, -200.01, 1e9, math.inf, -math.inf, math.nan])
def test_reference_outside_the_range_is_a_usage_error(percent: float) -> None:
    with pytest.raises(UsageError):
        encode_reference(percent)


@given(st.integers(0, 0xFFFF))
def test_every_raw_reference_survives_decode_then_encode(raw: int) -> None:
    percent = decode_reference(raw)
    assert -200.0 <= percent < 200.0
    assert encode_reference(percent) == raw


@given(st.floats(-200.0, 32767 * 100 / 16384))
@settings(max_examples=300)
def test_every_percentage_survives_encode_then_decode_within_half_a_step(percent: float) -> None:
    raw = encode_reference(percent)
    assert 0 <= raw <= 0xFFFF
    assert abs(decode_reference(raw) - percent) <= 100 / 16384 / 2 + 1e-12


@pytest.mark.parametrize(
    ("word", "stopping"),
    [
        (0x043C, Motion.STOP),  # ramp stop (§8.3)
        (0x0474, Motion.COAST),
        (0x046C, Motion.QUICK_STOP),
        (0x0478, Motion.STOP),  # DC brake, then stopped
        (0x0400, Motion.COAST),  # every stop at once: the output is off
        (0x047C, None),  # start: motion
        (0x847C, None),
        (0x057C, None),  # jog
        (0x045C, None),  # freeze: holds its output
        (0x0000, None),  # no valid word: nothing to say
        (0x003C, None),
    ],
)
def test_executed_motion_names_the_stop_a_valid_word_commands(
    word: int, stopping: Motion | None
) -> None:
    assert executed_motion(word) is stopping


@pytest.mark.parametrize("intent", [ControlIntent(m) for m in Motion])
def test_executed_motion_reads_back_each_word_the_master_sends(intent: ControlIntent) -> None:
    stopping = (
        intent.motion if intent.motion in (Motion.STOP, Motion.COAST, Motion.QUICK_STOP) else None
    )
    assert executed_motion(control_word(intent)) is stopping
