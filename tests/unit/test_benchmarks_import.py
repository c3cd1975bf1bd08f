"""Every benchmark still imports: a room of the house that moved must not leave one behind.

Benchmarks are run by hand, not by the test suite, so an import that a restructuring broke
would otherwise be found only by the next person who wants a figure.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


@pytest.mark.parametrize("path", sorted(BENCHMARKS.glob("*.py")), ids=lambda p: p.stem)
def test_the_benchmark_imports(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(BENCHMARKS))  # they import each other by name
    module = importlib.import_module(path.stem)
    try:
        assert module.__file__ is not None
        assert Path(module.__file__).resolve() == path
    finally:
        sys.modules.pop(path.stem, None)
