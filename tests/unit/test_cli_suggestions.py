"""Mistakes on the command line: the nearest known word, and no traceback for a failed file."""

from __future__ import annotations

import pytest

from fcmaster.cli import main


@pytest.mark.parametrize(
    ("argv", "hint"),
    [
        (["scna"], "(did you mean 'scan'?)"),
        (["scan", "--port", "x", "--protocol", "enk"], "(did you mean 'enc'?)"),
        (["scan", "--port", "x", "--adress", "3"], "(did you mean '--addresses'?)"),
        (["sim", "--faults", "drp=0.1"], "(did you mean 'drop'?)"),
        (["control", "--port", "x", "--address", "1", "start", "--frequncy", "5"],
         "(did you mean '--frequency'?)"),
    ],
)  # fmt: skip
def test_a_misspelling_is_refused_with_the_nearest_known_word(
    argv: list[str], hint: str, capsys: pytest.CaptureFixture[str]
) -> None:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own refusal
        code = int(exc.code or 0)
    assert code == 2
    assert hint in capsys.readouterr().err


def test_nothing_close_gets_no_guess(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["xyzzy"])
    assert "did you mean" not in capsys.readouterr().err


def test_a_file_that_fails_after_its_checks_is_said_without_a_traceback(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from fcmaster import cli

    def full_disk(_: object) -> int:
        raise OSError(28, "No space left on device", "/var/backup/pump.yaml")

    monkeypatch.setitem(cli.COMMANDS, "ports", full_disk)
    assert main(["ports"]) == 1
    assert capsys.readouterr().err == (
        "fcmaster ports: /var/backup/pump.yaml: No space left on device\n"
    )
