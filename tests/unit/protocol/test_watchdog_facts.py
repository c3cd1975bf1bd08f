"""Each vendor's watchdog facts: raw parameter values as the manuals define them → setting.

The raw values and their meanings are taken from the manuals (protocols/*.md), not from the
modules under test: FC 8-03 is a Uint32 in 0.1 s and 8-04 an option list (FC 102
programming guide); Mitsubishi Pr.122 is 0.1-999.8 s in 0.1 s, 9999 = no check, and travels
as HFFFF; ENC F2.16 is 0.0-1000.0 s in 0.1 s steps, 0.0 = off.
"""

from __future__ import annotations

import pytest

from fcmaster.errors import UsageError
from fcmaster.protocol.danfoss_fc import ResponseAk, Telegram, encode_telegram, make_pke
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.danfoss_fc.watchdog import WATCHDOG as FC
from fcmaster.protocol.enc.parameters import FUNCTION_CODES
from fcmaster.protocol.enc.watchdog import WATCHDOG as ENC
from fcmaster.protocol.mitsubishi.parameters import lookup as mitsubishi_lookup
from fcmaster.protocol.mitsubishi.watchdog import WATCHDOG as MITSUBISHI
from fcmaster.protocol.watchdog import WatchdogSetting


def _fc_read(pnu: int, pwe: int) -> float:
    """A parameter value as the FC codec decodes a drive's reply carrying raw ``pwe``."""
    codec = FcCodec()
    (exchange,) = codec.read(1, codec.parameter(f"{pnu // 100}-{pnu % 100:02d}"), 0, None)
    ak = ResponseAk.VALUE_DWORD if pnu == 803 else ResponseAk.VALUE_WORD
    frame = encode_telegram(
        Telegram(address=1, pcd1=0x0607, pcd2=0, pke=make_pke(ak, pnu), ind=0, pwe=pwe)
    )
    value = codec.parse(exchange, frame).value
    assert value is not None
    assert not isinstance(value.value, str)
    return float(value.value)


def test_fc_reads_the_timeout_time_first_then_the_function() -> None:
    assert FC.parameters == ("8-03", "8-04")


@pytest.mark.parametrize(
    ("raw_time", "option", "expected"),
    [
        # FC 102 factory settings: 60.0 s (raw 600 in 0.1 s) and [0] Off
        (600, 0, WatchdogSetting(timeout_s=None, action="off", stops=False)),
        (20, 2, WatchdogSetting(timeout_s=2.0, action="stop", stops=True)),
        (15, 5, WatchdogSetting(timeout_s=1.5, action="stop and trip", stops=True)),
        (10, 1, WatchdogSetting(timeout_s=1.0, action="freeze output", stops=False)),
        (10, 3, WatchdogSetting(timeout_s=1.0, action="jogging", stops=False)),
        (10, 4, WatchdogSetting(timeout_s=1.0, action="max. speed", stops=False)),
        (10, 7, WatchdogSetting(timeout_s=1.0, action="select set-up 1", stops=None)),
        (10, 10, WatchdogSetting(timeout_s=1.0, action="select set-up 4", stops=None)),
        (180000, 2, WatchdogSetting(timeout_s=18000.0, action="stop", stops=True)),
    ],
    ids=["factory-off", "stop", "stop-and-trip", "freeze", "jog", "max-speed", "setup-1",
         "setup-4", "five-hours"],
)  # fmt: skip
def test_fc_raw_values_decode_through_the_codec(
    raw_time: int, option: int, expected: WatchdogSetting
) -> None:
    values = [_fc_read(803, raw_time), _fc_read(804, option)]
    assert FC.decode(values) == expected


def test_fc_writes_the_time_before_the_function() -> None:
    assert FC.encode(3.0, "stop") == (("8-03", 3.0), ("8-04", 2))
    assert FC.encode(0.5, "trip") == (("8-03", 0.5), ("8-04", 5))


@pytest.mark.parametrize(
    ("timeout_s", "action", "words"),
    [
        (0.0, "stop", "outside"),
        (18000.1, "stop", "outside"),
        (1.25, "stop", "0.1 s steps"),
        (2.0, "freeze", "not one of"),
        (2.0, "off", "not one of"),
    ],
)
def test_fc_refuses_what_it_cannot_write_as_it_is(
    timeout_s: float, action: str, words: str
) -> None:
    with pytest.raises(UsageError, match=words):
        FC.encode(timeout_s, action)


@pytest.mark.parametrize(
    ("raw", "expected"),
    [
        (0xFFFF, WatchdogSetting(timeout_s=None, action="off", stops=False)),  # 9999
        (0, WatchdogSetting(timeout_s=0.0, action="trip", stops=True)),  # trips when commanded
        (1, WatchdogSetting(timeout_s=0.1, action="trip", stops=True)),
        (25, WatchdogSetting(timeout_s=2.5, action="trip", stops=True)),
        (9998, WatchdogSetting(timeout_s=999.8, action="trip", stops=True)),
    ],
    ids=["9999-no-check", "zero", "0.1s", "2.5s", "999.8s"],
)
def test_mitsubishi_pr122_raw_data_decodes(raw: int, expected: WatchdogSetting) -> None:
    assert MITSUBISHI.parameters == ("Pr.122",)
    assert MITSUBISHI.decode([mitsubishi_lookup(122).to_value(raw)]) == expected


def test_mitsubishi_writes_pr122_and_only_trips() -> None:
    assert MITSUBISHI.encode(2.0, "trip") == (("Pr.122", 2.0),)
    with pytest.raises(UsageError, match="outside"):
        MITSUBISHI.encode(999.9, "trip")
    with pytest.raises(UsageError, match="not one of"):
        MITSUBISHI.encode(2.0, "stop")


@pytest.mark.parametrize(
    ("raw", "expected"),
    [
        (0, WatchdogSetting(timeout_s=None, action="off", stops=False)),  # factory 0.0 s
        (5, WatchdogSetting(timeout_s=0.5, action="trip", stops=True)),
        (10000, WatchdogSetting(timeout_s=1000.0, action="trip", stops=True)),
    ],
    ids=["off", "0.5s", "1000s"],
)
def test_enc_f216_raw_value_decodes(raw: int, expected: WatchdogSetting) -> None:
    assert ENC.parameters == ("F2.16",)
    assert ENC.decode([FUNCTION_CODES[0x0210].to_value(raw)]) == expected


def test_enc_writes_f216_and_refuses_off() -> None:
    assert ENC.encode(1.5, "trip") == (("F2.16", 1.5),)
    with pytest.raises(UsageError, match="outside"):
        ENC.encode(0.0, "trip")


@pytest.mark.parametrize("facts", [FC, MITSUBISHI, ENC], ids=["fc", "mitsubishi", "enc"])
def test_advice_names_the_parameter_and_the_time(facts: object) -> None:
    from fcmaster.protocol.watchdog import WatchdogFacts

    assert isinstance(facts, WatchdogFacts)
    advice = facts.advice(1.2)
    assert facts.parameters[0] in advice
    assert "1.2 s" in advice
