"""`fcmaster events`: the journal file of a config, read while no daemon runs."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from fcmaster.cli import main
from fcmaster.store import Row, SequenceStore

CONFIG = """
buses:
  - name: line1
    port: /dev/ttyUSB0
    drives:
      - {{name: pump-1, address: 1, control: bus}}
{journal}
"""


def _plant(tmp_path: Path, journal: str) -> Path:
    path = tmp_path / "plant.yaml"
    path.write_text(CONFIG.format(journal=journal))
    return path


def _journal(path: Path) -> None:
    store = SequenceStore(path, table="journal", max_bytes=1 << 20, max_age_s=1e9)
    store.open()
    at = time.time()
    store.append(
        [
            Row(at - 7200, "start", None, None, '{"lines":1,"drives":1}'),
            Row(at - 60, "alarm", "line1", "pump-1", json.dumps({
                "code": 14, "text": "Earth fault", "active": True,
            })),
            Row(at - 30, "command", "line1", "pump-1", json.dumps({
                "actor": "ops", "action": "stop", "outcome": "done", "reason": "",
            })),
        ]
    )  # fmt: skip
    store.close()


def test_the_records_print_newest_last_filtered_as_asked(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _journal(tmp_path / "journal.db")
    config = _plant(tmp_path, "journal: {path: journal.db}")  # beside the config file
    assert main(["events", "--config", str(config)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[1] for line in lines] == ["start", "alarm", "command"]
    assert lines[1].endswith("line1/pump-1             14 Earth fault raised")
    assert "stop by ops → done" in lines[2]
    assert main(["events", "--config", str(config), "--since", "1h", "--json"]) == 0
    records = json.loads(capsys.readouterr().out)
    assert [(r["kind"], r["drive"]) for r in records] == [
        ("alarm", "pump-1"), ("command", "pump-1"),
    ]  # fmt: skip
    assert main(["events", "--config", str(config), "--kind", "alarm", "--json"]) == 0
    assert [r["code"] for r in json.loads(capsys.readouterr().out)] == [14]


def test_mistakes_are_named_and_a_journal_in_memory_points_to_the_daemon(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    in_memory = _plant(tmp_path, "")
    assert main(["events", "--config", str(in_memory)]) == 2
    assert "GET /api/v1/events" in capsys.readouterr().err
    config = _plant(tmp_path, "journal: {path: journal.db}")
    assert main(["events", "--config", str(config), "--since", "yesterday"]) == 2
    assert "--since: 'yesterday' is neither a time" in capsys.readouterr().err
    assert main(["events", "--config", str(config), "--kind", "alarms"]) == 2
    assert "--kind: 'alarms' is not one of command, alarm" in capsys.readouterr().err
    assert main(["events", "--config", str(config)]) == 1  # no file yet
    assert "no journal at" in capsys.readouterr().err
