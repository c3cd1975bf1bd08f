"""`fcmaster check --config FILE` end to end: the real command line, its output, its exit code.

tests/unit/test_config.py covers every kind of problem through ``config.parse``; this module
checks what a user at a shell sees: the summary with each line's worst-case poll round (the
figures computed here by hand from the wire format), and every problem of a bad file on
stderr with exit 2.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from fcmaster.cli import DEMO_CONFIG

GOOD = """
buses:
  - name: hall
    port: /dev/ttyUSB0
    baudrate: 19200
    parity: E
    drives:
      - {name: pump-1, address: 1, control: bus}
      - {name: pump-2, address: 2}
  - name: roof
    port: socket://10.0.0.7:4001
    baudrate: 9600
    response_delay_ms: 20
    drives:
      - {name: fan-1, address: 7}
      - {name: fan-2, address: 8}
      - {name: fan-3, address: 9}
http:
  listen: 127.0.0.1:8080
metrics: {enabled: true}
"""

BAD = """
buses:
  - name: hall
    port: ${FCM_TEST_UNSET_PORT}
    protocol: profibus
    drives:
      - {name: pump-1, address: 131}
      - {name: pump-1, address: 2, monitor: ["16-13", "sixteen"]}
      - {name: pump-3, address: 3, colour: red}
"""


def _check(config: Path) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k != "FCM_TEST_UNSET_PORT"}
    return subprocess.run(
        [sys.executable, "-m", "fcmaster", "check", "--config", str(config)],
        capture_output=True, text=True, timeout=60, env=env, check=False,
    )  # fmt: skip


def _poll_ms(baudrate: int, response_delay_ms: float) -> float:
    """One FC poll: 16-byte request, 16-byte reply, 8E1 (11 bits), a 2-character pause."""
    char_ms = 11 / baudrate * 1000
    return (16 + 16) * char_ms + response_delay_ms + 2 * char_ms


def test_a_good_file_exits_0_with_a_summary_and_each_lines_worst_case_poll_round(
    tmp_path: Path,
) -> None:
    config = tmp_path / "plant.yaml"
    config.write_text(GOOD)
    result = _check(config)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    out = result.stdout.splitlines()
    assert out[0] == f"{config}: valid"
    hall = 2 * _poll_ms(19200, 10)  # 58.96 ms
    roof = 3 * _poll_ms(9600, 20)  # 176.9 ms
    assert out[1].startswith("  hall: /dev/ttyUSB0, danfoss-fc, 19200 baud 8E1, 2 drive(s)")
    assert "(1 under bus control)" in out[1]
    assert out[2].startswith(f"    every drive polled within {hall:.1f} ms;")
    assert out[3].startswith("  roof: socket://10.0.0.7:4001, danfoss-fc, 9600 baud 8E1, 3 drive")
    assert out[4].startswith(f"    every drive polled within {roof:.1f} ms;")
    # Seven monitored values by default, one per poll: a full refresh takes seven rounds.
    assert out[4].endswith(f"every monitored value refreshed within {7 * roof / 1000:.2f} s")
    assert out[5] == "  adapters: http, metrics; on_shutdown: hold"
    # An unanswered FC probe (8-byte telegrams): its deadline, then a late reply's drain.
    roof_probe_s = 24 * 11 / 9600 + 0.020 + 0.050 + 3.5 * 11 / 9600
    assert 2 * roof_probe_s / 0.08 < 5.0  # so the 5 s probe interval is the longest wait
    assert out[6] == (
        "  hall: an absent drive is probed within 5.0 s even with all others but one absent "
        "(probes take at most 8% of the line while drives answer)"
    )
    assert out[7].startswith("  roof: an absent drive is probed within 5.0 s")


def test_check_says_how_long_a_drive_may_wait_when_all_the_others_stop_answering(
    tmp_path: Path,
) -> None:
    drives = "\n".join(f"      - {{name: d{a}, address: {a}, control: bus}}" for a in range(1, 33))
    config = tmp_path / "long.yaml"
    config.write_text(
        f"buses:\n  - name: long\n    port: /dev/ttyUSB0\n    baudrate: 19200\n    timeout_s: 0.1\n"
        f"    drives:\n{drives}\n"
    )
    result = _check(config)
    assert result.returncode == 0, result.stderr
    # Each of the other 31 misses its FC parameter poll (16-byte reply, 8E1 at 19200): the
    # user's 0.1 s deadline, then the reply's length and a 3.5-character gap for a late one.
    char_s = 11 / 19200
    miss_s = 0.1 + 16 * char_s + 3.5 * char_s
    assert (
        f"  long: should all other drives stop answering at once (a cabinet's supply cut), "
        f"a drive may wait up to {31 * miss_s:.1f} s for its poll, once, while each of them is "
        "tried"
    ) in result.stdout.splitlines()


def test_the_shipped_demo_config_is_valid() -> None:
    result = _check(DEMO_CONFIG)
    assert result.returncode == 0, result.stderr
    assert "line1: sim://line1" in result.stdout
    assert "line2: sim://line2" in result.stdout


def test_a_bad_file_exits_2_naming_every_problem_by_its_key_path(tmp_path: Path) -> None:
    config = tmp_path / "plant.yaml"
    config.write_text(BAD)
    result = _check(config)
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert lines[0] == "fcmaster check: invalid configuration"
    assert "  buses[0].port: environment variable FCM_TEST_UNSET_PORT is not set" in lines

    config.write_text(BAD.replace("${FCM_TEST_UNSET_PORT}", "/dev/ttyUSB0"))
    result = _check(config)
    assert result.returncode == 2
    problems = dict(line.strip().split(": ", 1) for line in result.stderr.splitlines()[1:])
    assert "buses[0].protocol" in problems
    assert "buses[0].drives[2].colour" in problems

    config.write_text(BAD.replace("${FCM_TEST_UNSET_PORT}", "/dev/ttyUSB0").replace(
        "    protocol: profibus\n", "").replace(", colour: red", ""))  # fmt: skip
    result = _check(config)
    assert result.returncode == 2
    problems = dict(line.strip().split(": ", 1) for line in result.stderr.splitlines()[1:])
    assert problems["buses[0].drives[0].address"] == "131 is outside 1-126"
    assert "already used" in problems["buses[0].drives[1].name"]
    assert "16-13" in problems["buses[0].drives[1].monitor[1]"]


def test_a_missing_file_exits_2_and_says_so(tmp_path: Path) -> None:
    result = _check(tmp_path / "nowhere.yaml")
    assert result.returncode == 2
    assert "nowhere.yaml: cannot read" in result.stderr


def test_check_refuses_what_run_refuses_and_every_bus_at_once(tmp_path: Path) -> None:
    config = tmp_path / "plant.yaml"
    config.write_text(
        GOOD.replace("baudrate: 19200", "baudrate: fast")
        .replace("{name: fan-3, address: 9}", "{name: fan-3, address: 131}")
        .replace("127.0.0.1:8080", "0.0.0.0:8080")
    )
    result = _check(config)
    assert result.returncode == 2
    problems = dict(line.strip().split(": ", 1) for line in result.stderr.splitlines()[1:])
    assert sorted(problems) == ["buses[0].baudrate", "buses[1].drives[2].address", "http.listen"]
    assert problems["buses[1].drives[2].address"] == "131 is outside 1-126"
    assert problems["http.listen"].startswith("0.0.0.0:8080 is not a loopback address")
