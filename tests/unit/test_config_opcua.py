"""The opcua section: keys, users beyond loopback, the None policy, the pki folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from fcmaster.adapters.settings import OPCUA_DEFAULT_SECURITY, OpcuaSettings, Token
from fcmaster.config import parse
from fcmaster.config_sections import OpcuaModel
from fcmaster.errors import ConfigError

LINE = """
buses:
  - name: line1
    port: sim://line1
    drives: [{name: pump-1, address: 1, control: bus}]
"""
TOKENS = """
http:
  tokens:
    - {name: scada, role: viewer, token: viewer-token-0123456789}
    - {name: ops, role: operator, token: operator-token-0123456789}
"""


def problems(text: str) -> list[tuple[str, str]]:
    with pytest.raises(ConfigError) as info:
        parse(text)
    return info.value.problems


def test_the_defaults_are_secure_and_resolve_pki_beside_the_file(tmp_path: Path) -> None:
    config = parse(LINE + TOKENS + "opcua: {pki: pki}\n", path=tmp_path / "plant.yaml")
    assert config.opcua == OpcuaSettings(
        pki=str(tmp_path / "pki"),
        users=(
            Token("scada", "viewer", "viewer-token-0123456789"),
            Token("ops", "operator", "operator-token-0123456789"),
        ),
    )
    assert config.opcua.security == OPCUA_DEFAULT_SECURITY
    assert "None" not in OPCUA_DEFAULT_SECURITY
    assert (config.opcua.anonymous, config.opcua.commands) == (False, False)
    assert OpcuaModel().settings("/var/lib/fcmaster/pki", ()) == OpcuaSettings()
    assert parse(LINE).opcua is None


def test_every_problem_is_named_by_its_key_at_once(tmp_path: Path) -> None:
    blocked = tmp_path / "file"
    blocked.write_text("")
    text = LINE + (
        "opcua:\n"
        "  listen: 0.0.0.0:4840\n"
        f"  pki: {blocked}/pki\n"
        "  security: [None, Basic256Sha256:SignAndEncrypt]\n"
        "  commands: true\n"
    )
    found = dict(problems(text))
    assert set(found) == {"opcua.listen", "opcua.security", "opcua.commands", "opcua.pki"}
    assert "http.tokens" in found["opcua.listen"]
    assert "None" in found["opcua.security"]
    assert "operator" in found["opcua.commands"]
    assert "cannot be created" in found["opcua.pki"]


def test_beyond_loopback_with_users_and_none_without_commands_are_accepted() -> None:
    text = LINE + TOKENS + "opcua: {listen: 0.0.0.0:4840, pki: /tmp, security: [None]}\n"
    assert parse(text).opcua is not None


@pytest.mark.parametrize(
    ("section", "key", "words"),
    [
        ("{security: [Basic128Rsa15]}", "opcua.security[0]", "Basic256Sha256:SignAndEncrypt"),
        ("{security: []}", "opcua.security", "at least 1"),
        ("{security: [None, None]}", "opcua.security", "more than once"),
        ("{listen: 'localhost'}", "opcua.listen", "127.0.0.1:4840"),
        ("{listen: '127.0.0.1:70000'}", "opcua.listen", "127.0.0.1:4840"),
        ("{anonymous: maybe}", "opcua.anonymous", "bool"),
        ("{write: true}", "opcua.write", ""),
    ],
)
def test_a_malformed_key_is_named(section: str, key: str, words: str) -> None:
    ((path, reason),) = [p for p in problems(LINE + f"opcua: {section}\n") if p[0] != "opcua.pki"]
    assert path == key
    assert words.lower() in reason.lower()


def test_an_unwritable_pki_folder_is_refused() -> None:
    # A folder nobody may write, root included (so the test means the same in CI).
    locked = Path("/proc/1")
    ((path, reason),) = problems(LINE + f"opcua: {{pki: {locked}}}\n")
    assert path == "opcua.pki"
    assert "cannot read and write" in reason


def test_a_pki_folder_that_cannot_be_created_is_refused() -> None:
    missing = Path("/proc/1/fcmaster-pki")
    ((path, reason),) = problems(LINE + f"opcua: {{pki: {missing}}}\n")
    assert path == "opcua.pki"
    assert "cannot be created in /proc/1" in reason


def test_a_pki_that_is_a_file_is_refused(tmp_path: Path) -> None:
    (tmp_path / "pki").write_text("")
    ((path, reason),) = problems(LINE + f"opcua: {{pki: {tmp_path / 'pki'}}}\n")
    assert (path, reason) == ("opcua.pki", f"{tmp_path / 'pki'} is not a folder")


def test_two_servers_on_one_port_are_refused_naming_the_second() -> None:
    clash = LINE + TOKENS.replace("http:\n", "http:\n  listen: 127.0.0.1:4841\n")
    found = problems(clash + "opcua: {listen: '127.0.0.1:4841', pki: /tmp}\n")
    assert [(k, r) for k, r in found if k == "opcua.listen"] == [
        ("opcua.listen", "port 4841 is http.listen's too: give each server its own")
    ]
    every = clash + "modbus: {listen: '0.0.0.0:4841', allow: [10.0.0.0/8]}\n"
    assert [k for k, _ in problems(every)] == ["modbus.listen"]
    apart = clash + "opcua: {listen: '127.0.0.1:4840', pki: /tmp}\n"
    assert parse(apart).opcua is not None
