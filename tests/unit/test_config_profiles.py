"""A drive's ``profile:`` in the config: built-in names, profile files, every problem named."""

from __future__ import annotations

from pathlib import Path

import pytest

from fcmaster.config import load, parse
from fcmaster.errors import ConfigError
from fcmaster.protocol.modbus_rtu.profiles import BUILT_IN
from tests.unit.protocol.modbus_rtu.test_profiles import USER_PROFILE


def config(protocol: str, profile: str | None, address: int = 1) -> str:
    key = "" if profile is None else f"\n        profile: {profile}"
    return f"""
buses:
  - name: line1
    port: /dev/ttyUSB0
    protocol: {protocol}
    drives:
      - name: d1
        address: {address}{key}
"""


def problems(text: str, path: Path | None = None) -> dict[str, str]:
    with pytest.raises(ConfigError) as caught:
        parse(text, path=path)
    return dict(caught.value.problems)


def test_a_built_in_profile_reaches_the_drives_plan() -> None:
    (line,) = parse(config("modbus-rtu", "altivar-cia402")).lines
    assert line.drives[0].profile is BUILT_IN["altivar-cia402"]


def test_a_modbus_drive_without_a_profile_is_refused_naming_the_built_ins() -> None:
    found = problems(config("modbus-rtu", None))
    assert "abb-drives" in found["buses[0].drives[0].profile"]


def test_a_profile_on_another_protocols_drive_is_refused() -> None:
    found = problems(config("danfoss-fc", "abb-drives"))
    assert "only drives on modbus-rtu lines" in found["buses[0].drives[0].profile"]


def test_an_unknown_name_is_refused() -> None:
    found = problems(config("modbus-rtu", "siemens"))
    assert "neither a built-in" in found["buses[0].drives[0].profile"]


def test_a_profile_file_beside_the_config_is_read(tmp_path: Path) -> None:
    (tmp_path / "my-vfd.yaml").write_text(USER_PROFILE, encoding="utf-8")
    file = tmp_path / "fcmaster.yaml"
    file.write_text(config("modbus-rtu", "my-vfd.yaml", address=247), encoding="utf-8")
    (line,) = load(file).lines
    profile = line.drives[0].profile
    assert getattr(profile, "name", None) == "my-vfd"


def test_a_broken_profile_file_names_the_key_the_file_and_its_key(tmp_path: Path) -> None:
    (tmp_path / "bad.yaml").write_text(
        USER_PROFILE.replace("fault: 9", "fault: 99"), encoding="utf-8"
    )
    found = problems(config("modbus-rtu", "bad.yaml"), path=tmp_path / "fcmaster.yaml")
    reason = found["buses[0].drives[0].profile"]
    assert str(tmp_path / "bad.yaml") in reason
    assert "status_bits.fault" in reason


def test_a_missing_profile_file_is_named(tmp_path: Path) -> None:
    found = problems(config("modbus-rtu", "gone.yaml"), path=tmp_path / "fcmaster.yaml")
    assert "cannot read" in found["buses[0].drives[0].profile"]


def test_a_modbus_address_beyond_247_is_refused() -> None:
    found = problems(config("modbus-rtu", "abb-drives", address=248))
    assert "248" in found["buses[0].drives[0].address"]


def test_the_lines_profile_serves_its_drives_without_one() -> None:
    text = config("modbus-rtu", None).replace(
        "protocol: modbus-rtu", "protocol: modbus-rtu\n    profile: yaskawa-memobus"
    )
    (line,) = parse(text).lines
    assert line.drives[0].profile is BUILT_IN["yaskawa-memobus"]
    assert dict(line.protocol_options)["profile"] == "yaskawa-memobus"
    found = problems(
        config("danfoss-fc", None).replace("protocol: danfoss-fc", "profile: abb-drives")
    )
    assert "only modbus-rtu lines have one" in found["buses[0].profile"]


def test_a_modbus_drives_watchdog_is_checked_against_its_profiles_actions() -> None:
    text = config("modbus-rtu", "abb-drives").replace(
        "address: 1",
        "address: 1\n        control: bus\n        watchdog: {timeout_s: 2.0, action: fault}",
    )
    (line,) = parse(text).lines
    watchdog = line.drives[0].watchdog
    assert watchdog is not None
    assert (watchdog.timeout_s, watchdog.action) == (2.0, "fault")
    found = problems(text.replace("action: fault", "action: warning"))
    assert "fault, fault always" in found["buses[0].drives[0].watchdog.action"]


def test_a_drive_without_a_monitor_list_watches_its_own_profiles_values() -> None:
    text = config("modbus-rtu", "altivar-cia402").replace(
        "    drives:\n", "    drives:\n      - {name: d0, address: 2, profile: abb-drives}\n"
    )
    (line,) = parse(text).lines
    by_name = {d.name: d for d in line.drives}
    assert by_name["d1"].monitor == ("hr3204", "hr3207", "hr3209")
    assert by_name["d0"].monitor == ("hr106", "hr109", "hr110")


def test_a_profile_file_is_found_beside_the_config_when_other_keys_are_broken(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The pass that checks the well-formed rest of a broken file reads profile files too:
    # from the config's folder, not from wherever the command runs.
    (tmp_path / "my-vfd.yaml").write_text(USER_PROFILE, encoding="utf-8")
    text = config("modbus-rtu", "my-vfd.yaml").replace(
        "    drives:\n",
        "    drives:\n      - {name: d0, address: 2, profile: abb-drives, "
        "nominal_frequency_hz: -1}\n",
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    found = problems(text, path=tmp_path / "fcmaster.yaml")
    assert list(found) == ["buses[0].drives[0].nominal_frequency_hz"]


def test_a_watchdog_on_a_drive_whose_profile_names_no_watchdog_registers_is_refused(
    tmp_path: Path,
) -> None:
    # Else `check` accepts it and the audit fails at run time: there is nowhere to write it.
    start, end = USER_PROFILE.index("watchdog:"), USER_PROFILE.index("values:")
    (tmp_path / "my-vfd.yaml").write_text(USER_PROFILE[:start] + USER_PROFILE[end:])
    text = config("modbus-rtu", "my-vfd.yaml").replace(
        "address: 1", "address: 1\n        control: bus\n        watchdog: {timeout_s: 1}"
    )
    found = problems(text, path=tmp_path / "fcmaster.yaml")
    assert list(found) == ["buses[0].drives[0].watchdog"]
    assert "names no watchdog registers" in found["buses[0].drives[0].watchdog"]
