"""Files a command will write, checked before it sends or reads anything."""

from __future__ import annotations

import os
from pathlib import Path

from fcmaster.errors import UsageError


def check_output(path: Path, option: str) -> None:
    """UsageError now if ``path`` (given as ``option``) cannot be written.

    Checked before a port is opened or a daemon asked, so a typo in a directory name does
    not cost a whole drive's read-out (``params backup``) or a capture's seconds.
    """
    parent = path.parent
    if path.is_dir():
        raise UsageError(f"{option} {path} is a directory: name a file in it")
    if not parent.is_dir():
        reason = "is not a directory" if parent.exists() else "does not exist"
        raise UsageError(f"{option} {path}: the directory {parent} {reason}; create it first")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {path}: no permission to write in {parent}")
    if path.exists() and not os.access(path, os.W_OK):
        raise UsageError(f"{option} {path}: the file exists and cannot be written")
