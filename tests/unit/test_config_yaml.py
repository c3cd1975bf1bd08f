"""The strict YAML reader under the config: nothing in a file may hide a value.

Keys given twice (at any depth), names equal but for case, alias bombs, aliases inside
themselves and nesting without end are each refused with the line named, through
``config.parse`` as ``fcmaster check`` and the daemon read a file.
"""

from __future__ import annotations

import textwrap

import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.config import parse
from fcmaster.config_yaml import MAX_DEPTH, read
from fcmaster.errors import ConfigError

DRIVE_TWICE = """\
buses:
  - name: line1
    port: /dev/ttyUSB0
    drives:
      - name: pump-1
        address: 1
        control: monitor
        max_frequency_hz: 50
        max_frequency_hz: 500
        control: bus
"""


def _problems(text: str) -> list[tuple[str, str]]:
    with pytest.raises(ConfigError) as info:
        parse(textwrap.dedent(text), env={})
    return info.value.problems


def bomb(levels: int = 10, width: int = 9) -> str:
    """About 1 KB of YAML whose aliases expand to ``width ** levels`` strings."""
    rows = [f"a0: &a0 [{', '.join(['lol'] * width)}]"]
    rows += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * width)}]" for i in range(1, levels)]
    rows.append(f"buses: [{{name: x, port: /dev/ttyUSB0, drives: *a{levels - 1}}}]")
    return "\n".join(rows) + "\n"


def test_a_limit_and_the_control_given_twice_are_refused_naming_both_lines() -> None:
    problems = _problems(DRIVE_TWICE)
    assert problems == [
        (
            "buses[0].drives[0].max_frequency_hz",
            "given twice, at line 8 and line 9: a key may appear once in a mapping "
            "(YAML would silently keep the second)",
        ),
        (
            "buses[0].drives[0].control",
            "given twice, at line 7 and line 10: a key may appear once in a mapping "
            "(YAML would silently keep the second)",
        ),
    ]


def test_a_second_buses_list_is_refused_with_the_other_problems() -> None:
    text = """\
    buses:
      - {name: line1, port: /dev/ttyUSB0, drives: [{name: a, address: 1}]}
    buses:
      - {name: line2, port: /dev/ttyUSB1, drives: [{name: b, address: 200}]}
    """
    problems = _problems(text)
    assert problems[0] == (
        "buses",
        "given twice, at line 1 and line 3: a key may appear once in a mapping "
        "(YAML would silently keep the second)",
    )
    assert problems[1][0] == "buses[0].drives[0].address"  # the rest is still checked


def test_a_quoted_key_is_the_same_key_and_a_number_is_another() -> None:
    problems = _problems(DRIVE_TWICE.replace("max_frequency_hz: 500", '"max_frequency_hz": 500'))
    assert problems[0][0] == "buses[0].drives[0].max_frequency_hz"
    twice: list[tuple[str, str]] = []
    data = read('"1": a\n1: b\n', twice)
    assert data == {"1": "a", 1: "b"}
    assert twice == []


def test_drive_and_bus_names_equal_but_for_case_are_refused() -> None:
    text = """\
    buses:
      - name: Line1
        port: /dev/ttyUSB0
        drives: [{name: Pump1, address: 1}, {name: PUMP1, address: 2}]
      - name: line1
        port: /dev/ttyUSB1
        drives: [{name: fan, address: 1}]
    """
    assert _problems(text) == [
        ("buses[0].drives[1].name",
         "drive name 'PUMP1' differs only in case from 'Pump1' at buses[0].drives[0].name"),
        ("buses[1].name", "bus name 'line1' differs only in case from 'Line1' at buses[0].name"),
    ]  # fmt: skip


def test_an_alias_bomb_is_refused_before_it_expands() -> None:
    text = bomb()
    assert len(text) < 1100
    ((where, reason),) = _problems(text)
    assert where == "line 2"  # the first alias
    assert "alias bomb" in reason
    assert "more than 100,000" in reason


def test_an_alias_inside_itself_is_refused() -> None:
    ((where, reason),) = _problems("buses: &loop [*loop]\n")
    assert where == "line 1"
    assert "refers to the node that contains it" in reason


def test_nesting_without_end_is_refused_at_the_bound() -> None:
    deep = 100_000
    ((where, reason),) = _problems("buses: " + "[" * deep + "]" * deep + "\n")
    assert where == "line 1"
    assert f"nested deeper than {MAX_DEPTH} levels" in reason
    block = "buses:\n" + "".join("  " * i + "-\n" for i in range(1, 200))
    ((where, reason),) = _problems(block)
    assert where == f"line {MAX_DEPTH + 1}"
    assert f"nested deeper than {MAX_DEPTH} levels" in reason


def test_aliases_that_nest_deeper_than_the_bound_are_refused() -> None:
    rows = ["n0: &n0 [x]"]
    rows += [f"n{i}: &n{i} [[[[[[[[*n{i - 1}]]]]]]]]" for i in range(1, 6)]  # 8 deeper each
    ((_, reason),) = _problems("\n".join(rows) + "\nbuses: []\n")
    assert f"deeper than {MAX_DEPTH} levels" in reason


def test_anchors_and_merge_keys_for_alike_drives_are_read() -> None:
    text = """\
    defaults: &pump {control: bus, max_frequency_hz: 50, on_start: stop}
    buses:
      - name: line1
        port: /dev/ttyUSB0
        drives:
          - {<<: *pump, name: pump-1, address: 1}
          - {<<: *pump, name: pump-2, address: 2, max_frequency_hz: 45}
    """
    twice: list[tuple[str, str]] = []
    data = read(textwrap.dedent(text), twice)
    assert twice == []
    drives = data["buses"][0]["drives"]
    assert drives[0]["max_frequency_hz"] == 50
    assert drives[1]["max_frequency_hz"] == 45  # written on the drive: it overrides the merge
    assert drives[1]["control"] == "bus"


@given(
    st.dictionaries(
        st.from_regex(r"[a-z_]{1,8}", fullmatch=True), st.integers(), min_size=1, max_size=6
    ),
    st.data(),
)
def test_any_key_written_twice_is_found_with_both_lines(
    mapping: dict[str, int], data: st.DataObject
) -> None:
    rows = [f"{key}: {value}" for key, value in mapping.items()]
    again = data.draw(st.sampled_from(sorted(mapping)))
    at = data.draw(st.integers(min_value=0, max_value=len(rows)))
    rows.insert(at, f"{again}: 0")
    text = "\n".join(rows) + "\n"
    assert yaml.safe_load(text)[again] is not None  # plain YAML takes it silently
    twice: list[tuple[str, str]] = []
    read(text, twice)
    lines = sorted(i + 1 for i, row in enumerate(rows) if row.startswith(f"{again}:"))
    assert twice == [
        (again, f"given twice, at line {lines[0]} and line {lines[1]}: a key may appear once "
         "in a mapping (YAML would silently keep the second)")
    ]  # fmt: skip
