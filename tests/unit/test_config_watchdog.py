"""The per-drive ``watchdog`` key: what is accepted, and every problem at its key."""

from __future__ import annotations

import textwrap

import pytest

from fcmaster.bus.plan import WatchdogPlan
from fcmaster.bus.poll_round import poll_round_s
from fcmaster.config import parse
from fcmaster.errors import ConfigError


def _config(protocol: str, drives: str, baudrate: int = 19200) -> str:
    return textwrap.dedent(
        f"""
        buses:
          - name: line1
            port: /dev/ttyUSB0
            protocol: {protocol}
            baudrate: {baudrate}
            drives:
        """
    ) + textwrap.indent(textwrap.dedent(drives), "      ")


def _problems(text: str) -> list[tuple[str, str]]:
    with pytest.raises(ConfigError) as info:
        parse(text)
    return info.value.problems


def test_a_watchdog_becomes_the_drive_plans_with_the_protocols_default_action() -> None:
    config = parse(
        _config(
            "danfoss-fc",
            """
            - {name: a, address: 1, control: bus, watchdog: {timeout_s: 2.5}}
            - {name: b, address: 2, control: bus, watchdog: {timeout_s: 1, action: trip}}
            - {name: c, address: 3, control: bus}
            """,
        )
    )
    a, b, c = config.lines[0].drives
    assert a.watchdog == WatchdogPlan(2.5, "stop")
    assert b.watchdog == WatchdogPlan(1.0, "trip")
    assert c.watchdog is None


@pytest.mark.parametrize("protocol", ["mitsubishi", "enc"])
def test_other_protocols_trip_by_default(protocol: str) -> None:
    config = parse(
        _config(protocol, "- {name: a, address: 1, control: bus, watchdog: {timeout_s: 3}}")
    )
    assert config.lines[0].drives[0].watchdog == WatchdogPlan(3.0, "trip")


def test_every_bad_watchdog_is_named_by_its_key_at_once() -> None:
    problems = _problems(
        _config(
            "danfoss-fc",
            """
            - {name: a, address: 1, control: bus, watchdog: {timeout_s: 0}}
            - {name: b, address: 2, control: bus, watchdog: {timeout_s: 2, action: freeze}}
            - {name: c, address: 3, watchdog: {timeout_s: 2}}
            - {name: d, address: 4, control: bus, watchdog: {timeout_s: 1.25}}
            - {name: e, address: 5, control: bus, watchdog: {timeout_s: 2, when: now}}
            """,
        )
    )
    where = dict(problems)
    assert "outside" in where["buses[0].drives[0].watchdog.timeout_s"]
    assert "freeze" in where["buses[0].drives[1].watchdog.action"]
    assert "control: bus" in where["buses[0].drives[2].watchdog"]
    assert "0.1 s steps" in where["buses[0].drives[3].watchdog.timeout_s"]
    assert "buses[0].drives[4].watchdog.when" in where


def test_mitsubishi_has_no_stop_action() -> None:
    problems = _problems(
        _config(
            "mitsubishi",
            "- {name: a, address: 1, control: bus, watchdog: {timeout_s: 2, action: stop}}",
        )
    )
    assert [p for p, _ in problems] == ["buses[0].drives[0].watchdog.action"]


def test_a_timeout_shorter_than_the_lines_worst_round_is_refused() -> None:
    # eight drives at 2400 baud: one round of polls takes far more than 0.5 s
    drives = "\n".join(
        f"- {{name: d{i}, address: {i}, control: bus, watchdog: {{timeout_s: "
        f"{0.5 if i in (2, 5) else 30}}}}}"
        for i in range(1, 9)
    )
    text = _config("danfoss-fc", drives, baudrate=2400)
    problems = _problems(text)
    assert [p for p, _ in problems] == [
        "buses[0].drives[1].watchdog.timeout_s",
        "buses[0].drives[4].watchdog.timeout_s",
    ]
    # the message gives the round it was compared with, as `check` computes it
    assert "worst-case poll round" in problems[0][1]
    ok = parse(text.replace("timeout_s: 0.5", "timeout_s: 30"))
    round_ms = poll_round_s(ok.lines[0])[0] * 1000
    assert 500 < round_ms < 30_000
    assert f"{round_ms:.1f} ms" in problems[0][1]


def test_mitsubishi_checks_the_same_actions_and_range_on_either_port() -> None:
    # what config_watchdog checks against is the same whichever port a line is wired to
    from fcmaster.protocol.mitsubishi.watchdog import DRIVE_PORTS, watchdog_for

    facts = [watchdog_for(port) for port in DRIVE_PORTS]
    assert {(f.actions, f.timeout_range_s) for f in facts} == {(("trip",), (0.1, 999.8))}
    assert {f.parameters for f in facts} == {("Pr.122",), ("Pr.336",)}
