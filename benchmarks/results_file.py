"""Where a benchmark's figures came from, and writing them as strict JSON.

Every results file under ``benchmarks/results/`` opens with the same provenance — the
commit, any uncommitted change under ``fcmaster/``, the Python, the machine — so a figure
can always be traced to the code and the machine that produced it.
"""

from __future__ import annotations

import json
import math
import os
import platform
import subprocess
import sys
import time
from collections.abc import Coroutine
from pathlib import Path
from typing import Any


def provenance(benchmark: str) -> dict[str, Any]:
    """The header every results file starts with."""
    return {
        "benchmark": benchmark,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "fcmaster_commit": _git("rev-parse", "--short", "HEAD"),
        "fcmaster_uncommitted": _git("status", "--porcelain", "--", ":/fcmaster").splitlines(),
        "cpus": os.cpu_count(),
    }


def write(path: Path, results: dict[str, Any]) -> None:
    """``results`` as indented strict JSON at ``path``.

    NaN (a figure with no samples) and infinity (a time that never came within the run)
    are written as null.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_finite(results), indent=2, allow_nan=False) + "\n")


def run_and_write(figures: Coroutine[Any, Any, dict[str, Any]], path: Path) -> None:
    """Run ``figures`` on fcmaster's event loop; write what it returns at ``path``."""
    import asyncio

    from fcmaster.clock import new_event_loop

    with asyncio.Runner(loop_factory=new_event_loop) as runner:
        found = runner.run(figures)
    write(path, found)
    print(f"wrote {path}", file=sys.stderr)


def _git(*args: str) -> str:
    """What git says about the tree the figures came from ("" outside a checkout)."""
    try:
        return subprocess.run(
            ["git", *args], cwd=Path(__file__).resolve().parent, capture_output=True,
            text=True, check=True, timeout=10,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return ""


def _finite(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value
