"""`fcmaster check` and the per-drive ``watchdog``: a timeout shorter than the line's worst-case
poll round is refused, with every other problem of the file at once (exit 2)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

CONFIG = """
buses:
  - name: slow
    port: /dev/ttyUSB0
    baudrate: 2400
    drives:
      - {name: pump-1, address: 1, control: bus, watchdog: {timeout_s: 0.4}}
      - {name: pump-2, address: 2, control: bus, watchdog: {timeout_s: 0.6}}
      - {name: pump-3, address: 3, control: bus, watchdog: {timeout_s: 2, action: freeze}}
  - name: fast
    port: /dev/ttyUSB1
    baudrate: 115200
    drives:
      - {name: fan-1, address: 1, control: bus, watchdog: {timeout_s: 0.1}}
      - {name: fan-2, address: 300}
"""


def _poll_ms(baudrate: int, response_delay_ms: float) -> float:
    """One FC poll: 16-byte request, 16-byte reply, 8E1 (11 bits), a 2-character pause."""
    char_ms = 11 / baudrate * 1000
    return (16 + 16) * char_ms + response_delay_ms + 2 * char_ms


def test_a_watchdog_shorter_than_the_round_is_refused_with_every_other_problem(
    tmp_path: Path,
) -> None:
    config = tmp_path / "plant.yaml"
    config.write_text(CONFIG)
    result = subprocess.run(
        [sys.executable, "-m", "fcmaster", "check", "--config", str(config)],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert result.returncode == 2, result.stdout
    problems = dict(line.strip().split(": ", 1) for line in result.stderr.splitlines()[1:])
    slow_ms = 3 * _poll_ms(2400, 10)  # 497.5 ms
    assert set(problems) == {
        "buses[0].drives[0].watchdog.timeout_s",  # 0.4 s < 497.5 ms
        "buses[0].drives[2].watchdog.action",
        "buses[1].drives[1].address",
    }
    assert problems["buses[0].drives[0].watchdog.timeout_s"] == (
        f"0.4 s is shorter than the line's worst-case poll round of {slow_ms:.1f} ms: "
        "normal polling would trip the drive"
    )
    assert "freeze" in problems["buses[0].drives[2].watchdog.action"]
