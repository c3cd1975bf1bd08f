"""`fcmaster check` on files that try to smuggle a value: the real command, as a user runs it.

Each file is refused with exit 2 and the line named, never with a traceback. The child runs
under an address-space limit far below what an expanded alias bomb takes, so a reader that
expanded it would fail with a MemoryError (a traceback, exit 1), not pass by being quick.
"""

from __future__ import annotations

import resource
import subprocess
import sys
from pathlib import Path

from tests.unit.test_config_yaml import DRIVE_TWICE, bomb

MEMORY_LIMIT = 1 << 30  # 1 GiB of address space: the interpreter needs a few hundred MiB


def _limited() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def _check(tmp_path: Path, text: str) -> tuple[int, list[str]]:
    config = tmp_path / "plant.yaml"
    config.write_text(text)
    result = subprocess.run(
        [sys.executable, "-m", "fcmaster", "check", "--config", str(config)],
        capture_output=True, text=True, timeout=120, check=False, preexec_fn=_limited,
    )  # fmt: skip
    assert "Traceback" not in result.stderr, result.stderr
    assert result.stdout == ""  # never "valid"
    lines = result.stderr.splitlines()
    assert lines[0] == "fcmaster check: invalid configuration"
    return result.returncode, lines[1:]


def test_a_limit_and_the_control_given_twice_exit_2_naming_both_lines(tmp_path: Path) -> None:
    code, problems = _check(tmp_path, DRIVE_TWICE)
    assert code == 2
    assert problems == [
        "  buses[0].drives[0].max_frequency_hz: given twice, at line 8 and line 9: a key may "
        "appear once in a mapping (YAML would silently keep the second)",
        "  buses[0].drives[0].control: given twice, at line 7 and line 10: a key may appear "
        "once in a mapping (YAML would silently keep the second)",
    ]


def test_a_second_buses_and_names_equal_but_for_case_exit_2_all_at_once(tmp_path: Path) -> None:
    text = (
        "buses:\n"
        "  - {name: line1, port: /dev/ttyUSB0, drives: [{name: a, address: 1}]}\n"
        "buses:\n"
        "  - {name: line1, port: /dev/ttyUSB0,"
        " drives: [{name: Pump1, address: 1}, {name: pump1, address: 2}]}\n"
    )
    code, problems = _check(tmp_path, text)
    assert code == 2
    assert problems == [
        "  buses: given twice, at line 1 and line 3: a key may appear once in a mapping "
        "(YAML would silently keep the second)",
        "  buses[0].drives[1].name: drive name 'pump1' differs only in case from 'Pump1' at "
        "buses[0].drives[0].name",
    ]


def test_an_alias_bomb_exits_2_refused_not_expanded(tmp_path: Path) -> None:
    text = bomb()  # 9 ** 10: 3.5 billion strings if expanded
    assert len(text) < 1100
    code, problems = _check(tmp_path, text)
    assert code == 2
    (problem,) = problems
    assert problem.startswith("  line 2: the aliases (*name) at line 2 and ")
    assert "refused as an alias bomb" in problem


def test_a_list_100000_deep_exits_2_with_a_message(tmp_path: Path) -> None:
    deep = 100_000
    code, problems = _check(tmp_path, "buses: " + "[" * deep + "]" * deep + "\n")
    assert code == 2
    assert problems == ["  line 1: nested deeper than 32 levels; a config needs far fewer"]
    code, problems = _check(tmp_path, "buses: &loop [*loop]\n")
    assert code == 2
    assert problems == [
        "  line 1: an alias refers to the node that contains it (anchored at line 1): it "
        "would never end"
    ]
