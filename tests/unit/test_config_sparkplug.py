"""The sparkplug section: its keys, what is wrong with them named by key path, its settings."""

from __future__ import annotations

from pathlib import Path

import pytest

from fcmaster.adapters.settings import SparkplugSettings
from fcmaster.config import ConfigModel, load, parse
from fcmaster.config_sections import SparkplugModel
from fcmaster.errors import ConfigError

LINE = """
buses:
  - name: line1
    port: sim://line1
    drives: [{name: pump-1, address: 1}]
"""


def problems(text: str) -> dict[str, str]:
    with pytest.raises(ConfigError) as info:
        parse(text)
    return dict(info.value.problems)


def test_the_keys_design_names_and_their_defaults() -> None:
    text = LINE + "sparkplug: {group_id: Plant, edge_node_id: gw-1, primary_host_id: scada}\n"
    settings = parse(text).sparkplug
    assert settings == SparkplugSettings(
        url="mqtt://127.0.0.1:1883",
        group_id="Plant",
        edge_node_id="gw-1",
        primary_host_id="scada",
        commands=False,
        store=None,
    )
    assert parse(LINE).sparkplug is None


def test_the_defaults_of_the_settings_are_the_configs() -> None:
    model = SparkplugModel(group_id="g", edge_node_id="e")
    assert model.settings(None) == SparkplugSettings(group_id="g", edge_node_id="e")


@pytest.mark.parametrize(
    ("section", "path", "words"),
    [
        ("{edge_node_id: gw}", "sparkplug.group_id", "required key is missing"),
        ("{group_id: g}", "sparkplug.edge_node_id", "required key is missing"),
        ("{group_id: a/b, edge_node_id: gw}", "sparkplug.group_id", "without + / or #"),
        ("{group_id: g, edge_node_id: 'gw+'}", "sparkplug.edge_node_id", "without + / or #"),
        (
            "{group_id: g, edge_node_id: gw, primary_host_id: '#'}",
            "sparkplug.primary_host_id",
            "+ / or #",
        ),
        ("{group_id: g, edge_node_id: gw, url: 'http://x'}", "sparkplug.url", "mqtt://host:port"),
        (
            "{group_id: g, edge_node_id: gw, url: 'mqtt://u:p@x'}",
            "sparkplug.url",
            "sparkplug.username",
        ),
        ("{group_id: g, edge_node_id: gw, tls: {}}", "sparkplug", "needs an mqtts:// url"),
        ("{group_id: g, edge_node_id: gw, commands: maybe}", "sparkplug.commands", "boolean"),
        (
            "{group_id: g, edge_node_id: gw, store_max_mb: 0}",
            "sparkplug.store_max_mb",
            "greater than 0",
        ),
        ("{group_id: g, edge_node_id: gw, topic: x}", "sparkplug.topic", "unknown key"),
    ],
)
def test_each_problem_is_named_by_its_key_path(section: str, path: str, words: str) -> None:
    found = problems(LINE + f"sparkplug: {section}\n")
    assert path in found, found
    assert words in found[path]


def test_an_unreadable_tls_file_is_named(tmp_path: Path) -> None:
    text = LINE + (
        "sparkplug: {group_id: g, edge_node_id: gw, url: 'mqtts://broker',"
        f" tls: {{ca: {tmp_path / 'nope.pem'}}}}}\n"
    )
    assert "cannot read" in problems(text)["sparkplug.tls.ca"]


def test_a_relative_store_is_taken_from_the_config_files_folder(tmp_path: Path) -> None:
    config = tmp_path / "plant.yaml"
    config.write_text(LINE + "sparkplug: {group_id: g, edge_node_id: gw, store: spool/sf.db}\n")
    settings = load(config).sparkplug
    assert settings is not None
    assert settings.store == str(tmp_path / "spool" / "sf.db")


def test_the_section_is_in_the_whole_files_model() -> None:
    assert "sparkplug" in ConfigModel.model_fields
