"""The doctor's conclusions: what it observed on a line → findings, each with its fix."""

from __future__ import annotations

import json

from fcmaster.subcommands.diagnosis import (
    AddressReport,
    Expected,
    LineFormat,
    Survey,
    diagnose,
    to_json,
    to_text,
)
from fcmaster.transport.usb import Adapter

FC_19200 = LineFormat(protocol="danfoss-fc", baudrate=19200, parity="E", stopbits=1,
                      protocol_options=(("address_format", 126),))  # fmt: skip


def answering(*addresses: int) -> list[AddressReport]:
    return [AddressReport(address=a, attempts=3, answered=3) for a in addresses]


def healthy(**changes: object) -> Survey:
    """Two drives answering cleanly at FC 19200 8E1, replies 10.4 ms after each request."""
    survey = Survey(
        port="/dev/ttyUSB0", found=FC_19200, settings_tried=13, addresses=answering(1, 2),
        requests=60, listened_s=3.0, turnarounds_s=[0.0104] * 6, scanned=list(range(1, 7)),
    )  # fmt: skip
    for key, value in changes.items():
        setattr(survey, key, value)
    return survey


def codes(survey: Survey) -> list[str]:
    return [finding.code for finding in diagnose(survey)]


def expected(**line: object) -> Expected:
    fields = {"protocol": "danfoss-fc", "baudrate": 19200, "parity": "E", "stopbits": 1,
              "protocol_options": (("address_format", 126),), **line}  # fmt: skip
    return Expected(bus="north", line=LineFormat(**fields), echo=False)  # type: ignore[arg-type]


def test_a_clean_line_has_no_findings_and_says_so() -> None:
    survey = healthy()
    assert diagnose(survey) == []
    text = to_text(survey, [])
    assert "line      danfoss-fc 19200 8E1, address format 126" in text
    assert "drives    1, 2" in text
    assert text[-1] == "healthy: nothing to fix"
    document = to_json(survey, [])
    assert document["healthy"] is True
    assert document["line"] == {"protocol": "danfoss-fc", "baudrate": 19200, "parity": "E",
                                "stopbits": 1, "address_format": 126}  # fmt: skip
    assert document["drives"] == [1, 2]
    assert document["turnaround_ms"] == 10.4


def test_no_answer_anywhere_is_the_only_line_finding() -> None:
    survey = Survey(port="/dev/ttyUSB0", settings_tried=63, requests=252, listened_s=20.0)
    [finding] = diagnose(survey)
    assert finding.code == "no_answer"
    assert "no drive answered on /dev/ttyUSB0 at any of 63 line settings" in finding.message
    assert "swap the A and B wires" in finding.fix
    assert to_json(survey, [finding])["healthy"] is False


def test_a_baud_rate_other_than_the_configs_says_which_key_to_set() -> None:
    [finding] = diagnose(healthy(expected=expected(baudrate=9600)))
    assert finding.code == "settings"
    assert finding.message == (
        "drives answer at 19200 8E1 (danfoss-fc) but the config (bus north) says baudrate 9600"
    )
    assert finding.fix == "set baudrate: 19200 on bus north"
    assert finding.to_json()["config"]["baudrate"] == 9600


def test_parity_and_protocol_differences_are_named_together() -> None:
    # A pty cannot carry parity, so this is the only place a parity mismatch is rehearsed
    # end to end in words; the search for it is tested in-process in test_doctor_search.
    found = LineFormat(protocol="danfoss-fc", baudrate=19200, parity="O", stopbits=1,
                       protocol_options=(("address_format", 126),))  # fmt: skip
    survey = healthy(found=found, expected=expected(parity="E"))
    [finding] = diagnose(survey)
    assert finding.fix == "set parity: O on bus north"
    survey = healthy(expected=expected(protocol="enc", baudrate=9600, parity="N"))
    [finding] = diagnose(survey)
    assert finding.fix == "set protocol: danfoss-fc, baudrate: 19200, parity: E on bus north"


def test_drives_that_know_only_the_31_format() -> None:
    found = LineFormat(protocol="danfoss-fc", baudrate=9600, parity="E", stopbits=1,
                       protocol_options=(("address_format", 31),))  # fmt: skip
    assert codes(healthy(found=found, only_options=(("address_format", 31),))) == ["address_format"]
    [finding] = diagnose(healthy(found=found, only_options=(("address_format", 31),)))
    assert "address_format: 31" in finding.fix
    # A config that says 9600 and format 126 gets one settings finding naming both keys.
    [finding] = diagnose(
        healthy(
            found=found, only_options=(("address_format", 31),), expected=expected(baudrate=9600)
        )
    )
    assert finding.fix == "set address_format: 31 on bus north"


def test_an_echo_heard_on_most_requests_asks_for_echo_true() -> None:
    [finding] = diagnose(healthy(echoes=58))
    assert finding.code == "echo"
    assert finding.message.startswith("the adapter echoes: 58 of 60 requests came back")
    assert finding.fix.startswith("set echo: true")
    assert diagnose(healthy(echoes=10)) == []  # a few are not an echoing adapter
    configured = expected()
    configured.echo = True
    assert diagnose(healthy(echoes=60, expected=configured)) == []
    [finding] = diagnose(healthy(echoes=0, expected=configured))
    assert (finding.code, finding.fix) == ("no_echo", "set echo: false on the bus")


def test_two_drives_at_one_address_name_the_address_parameter_and_a_free_address() -> None:
    twins = AddressReport(address=2, attempts=3, garbled=3)
    [finding] = diagnose(healthy(addresses=[*answering(1), twins, *answering(3)]))
    assert finding.code == "duplicate_address"
    assert finding.message == "two drives answer at address 2 (garbled replies in 3 of 3 attempts)"
    assert (
        finding.fix == "give one of them another address with 8-31 (e.g. 4, where nothing answered)"
    )
    assert finding.to_json()["address"] == 2
    found = LineFormat(protocol="mitsubishi", baudrate=19200, parity="E", stopbits=2)
    [finding] = diagnose(healthy(found=found, addresses=[twins], turnarounds_s=[]))
    assert "Pr.117" in finding.fix
    # Where every address scanned is taken, no free one is suggested (others were not asked).
    [finding] = diagnose(healthy(addresses=[twins, *answering(3)], scanned=[2, 3]))
    assert finding.fix == "give one of them another address with 8-31"


def test_collisions_are_judged_over_attempts() -> None:
    assert AddressReport(address=1, attempts=3, answered=2, doubled=1).collides
    assert AddressReport(address=1, attempts=3, garbled=2, answered=1).collides
    assert not AddressReport(address=1, attempts=3, garbled=1, answered=2).collides  # a hit
    assert not AddressReport(address=1, attempts=1, garbled=1).collides
    [finding] = diagnose(healthy(addresses=[AddressReport(address=7, attempts=3, doubled=2,
                                                          answered=1)]))  # fmt: skip
    assert "doubled replies in 2 of 3 attempts" in finding.message


def test_noise_is_counted_and_rated_from_a_few_bytes_up() -> None:
    assert diagnose(healthy(noise_bytes=2)) == []
    [finding] = diagnose(healthy(noise_bytes=30))
    assert finding.code == "noise"
    assert finding.message == (
        "30 bytes of noise outside frames (50 per 100 requests, 10.0 per second of listening)"
    )
    assert "120 ohm" in finding.fix
    assert finding.to_json()["noise_bytes"] == 30


def test_a_high_latency_timer_gives_the_udev_rule() -> None:
    adapter = Adapter(device="/dev/ttyUSB0", driver="ftdi_sio", by_id=None, by_path=None,
                      latency_ms=16)  # fmt: skip
    # Slow replies too, but the timer explains them: one finding, not two.
    [finding] = diagnose(healthy(adapter=adapter, turnarounds_s=[0.019] * 5))
    assert finding.code == "adapter_latency"
    assert finding.message == (
        "16 ms latency timer on /dev/ttyUSB0 (ftdi_sio): at most about 62 transactions/s"
    )
    assert 'ATTR{latency_timer}="1"' in finding.fix
    low = Adapter(device="/dev/ttyUSB0", driver="ftdi_sio", by_id=None, by_path=None,
                  latency_ms=1)  # fmt: skip
    assert diagnose(healthy(adapter=low)) == []


def test_replies_held_beyond_the_drives_delay_are_slow() -> None:
    [finding] = diagnose(healthy(turnarounds_s=[0.011, 0.019, 0.021, 0.024, 0.012]))
    assert finding.code == "slow_replies"
    assert finding.message.startswith("the drives answer 19.0 ms after a request ends, 9.0 ms")
    assert "latency timer" in finding.fix
    assert "8-35" in finding.fix
    assert diagnose(healthy(turnarounds_s=[0.0105, 0.012, 0.030])) == []  # 12 ms: in margin
    # Through a TCP converter the network's round trip is in every turnaround.
    remote = healthy(port="socket://10.0.0.7:4001", turnarounds_s=[0.030] * 3)
    assert diagnose(remote) == []


def test_the_json_report_carries_every_finding() -> None:
    survey = healthy(echoes=60, noise_bytes=9, expected=expected(baudrate=9600))
    findings = diagnose(survey)
    document = json.loads(json.dumps(to_json(survey, findings)))
    assert [f["code"] for f in document["findings"]] == ["settings", "echo", "noise"]
    assert all(f["message"] and f["fix"] for f in document["findings"])
    assert document["config_bus"] == "north"
    assert document["healthy"] is False
