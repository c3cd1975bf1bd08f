"""One unit for a drive's output: every codec's reply carries Hz, scaled by the drive's nominal.

The FC main actual value is a percentage of the nominal frequency (0x4000 = 100 %, §8.5),
so an FC line's codec is told each drive's nominal; Mitsubishi and ENC read Hz directly.
"""

from __future__ import annotations

from fractions import Fraction

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.bus.codecs import codec_for
from fcmaster.bus.plan import DrivePlan, LinePlan
from fcmaster.protocol.danfoss_fc import Telegram, encode_telegram
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.drive import hz_to_pct, pct_to_hz

STATUS_RUNNING = 0x0F07  # ready, running, at reference, bus control


def fc_reply(codec: FcCodec, address: int, mav: int) -> float | None:
    (exchange,) = codec.control(address, None)
    frame = encode_telegram(Telegram(address=address, pcd1=STATUS_RUNNING, pcd2=mav))
    return codec.parse(exchange, frame).output_frequency_hz


@pytest.mark.parametrize(
    ("nominal_hz", "mav", "hz"),
    [
        pytest.param(60.0, 0x2000, 30.0, id="half-of-60"),
        pytest.param(50.0, 0x4000, 50.0, id="all-of-50"),
        pytest.param(87.0, 0x4000, 87.0, id="all-of-87"),
        pytest.param(50.0, 0x0001, 50.0 / 16384, id="one-step"),
        pytest.param(60.0, 0xE000, -30.0, id="reverse-half-of-60"),
        pytest.param(50.0, 0x0000, 0.0, id="stopped"),
    ],
)
def test_an_fc_reply_carries_the_main_actual_value_in_hz_of_the_drives_nominal(
    nominal_hz: float, mav: int, hz: float
) -> None:
    assert fc_reply(FcCodec(nominal_hz={7: nominal_hz}), 7, mav) == hz


def test_an_fc_drive_without_a_nominal_is_read_at_50_hz() -> None:
    assert fc_reply(FcCodec(nominal_hz={1: 60.0}), 2, 0x2000) == 25.0


def test_the_sign_of_the_fc_output_still_tells_the_direction() -> None:
    codec = FcCodec(nominal_hz={1: 60.0})
    (exchange,) = codec.control(1, None)
    frame = encode_telegram(Telegram(address=1, pcd1=STATUS_RUNNING, pcd2=0xE000))
    status = codec.parse(exchange, frame).status
    assert status is not None
    assert status.reverse is True


def test_an_fc_line_from_its_plan_reads_each_drive_at_its_own_nominal() -> None:
    drives = (
        DrivePlan(name="a", address=1, nominal_frequency_hz=60.0, max_frequency_hz=60.0),
        DrivePlan(name="b", address=2, nominal_frequency_hz=87.0, max_frequency_hz=87.0),
    )
    codec = codec_for(LinePlan(name="line1", port="test", drives=drives))
    assert isinstance(codec, FcCodec)
    assert fc_reply(codec, 1, 0x2000) == 30.0
    assert fc_reply(codec, 2, 0x2000) == 43.5


def test_the_conversion_is_exact_on_fractions() -> None:
    assert pct_to_hz(Fraction(1, 3), Fraction(50)) == Fraction(1, 6)
    assert hz_to_pct(Fraction(1, 6), Fraction(50)) == Fraction(1, 3)


def test_percent_and_hz_of_a_nominal() -> None:
    assert pct_to_hz(50.0, 60.0) == 30.0
    assert hz_to_pct(30.0, 60.0) == 50.0
    assert pct_to_hz(-25.0, 50.0) == -12.5


@given(
    pct=st.floats(min_value=-200.0, max_value=200.0),
    nominal_hz=st.floats(min_value=1.0, max_value=600.0),
)
def test_percent_to_hz_and_back_is_the_same_percent(pct: float, nominal_hz: float) -> None:
    assert hz_to_pct(pct_to_hz(pct, nominal_hz), nominal_hz) == pytest.approx(pct, abs=1e-9)
