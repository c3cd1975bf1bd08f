"""Eclipse Tahu's JavaScript Sparkplug B codec (npm ``sparkplug-payload``) as a peer decoder.

``tests/node/sparkplug`` holds it, pinned (``npm ci`` there; .ci/run does it). Without node
or the installed package a test is skipped, except under ``CI=true``, where it fails.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest

FOLDER = Path(__file__).resolve().parent.parent / "node" / "sparkplug"
TIMEOUT_S = 60.0


def tahu_marks() -> list[pytest.MarkDecorator]:
    """A module's marks: none when Tahu's codec is installed, else a skip; under CI, an error."""
    node = shutil.which("node")
    if node is not None and (FOLDER / "node_modules" / "sparkplug-payload").is_dir():
        return []
    why = f"needs node and `npm ci` in {FOLDER}"
    if os.environ.get("CI") == "true":
        raise RuntimeError(f"the Sparkplug peer tests {why}")
    return [pytest.mark.skip(reason=why)]


def tahu_decode(payloads: list[bytes]) -> list[dict[str, Any]]:
    """Each payload as Tahu's ``decodePayload`` reads it, as JSON (Longs as decimal strings)."""
    done = subprocess.run(
        ["node", str(FOLDER / "decode.js")],
        input="".join(p.hex() + "\n" for p in payloads),
        capture_output=True, text=True, check=True, timeout=TIMEOUT_S,
    )  # fmt: skip
    # Not splitlines: U+2028 is text. Every integer Tahu prints as a number has 32 bits (64-bit
    # ones are strings), so a longer one is a Float or Double that JavaScript printed whole.
    decoded = [json.loads(line, parse_int=_number) for line in done.stdout.split("\n") if line]
    assert len(decoded) == len(payloads), done.stderr
    return decoded


def _number(text: str) -> int | float:
    value = int(text)
    return float(value) if abs(value) >= 1 << 53 else value
