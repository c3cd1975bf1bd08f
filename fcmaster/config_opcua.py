"""The ``opcua`` section's checks that need the whole file: users, commands, the pki folder.

OPC UA users are the ``http.tokens``, so who may connect from beyond this machine, and who
may call a method, depends on the ``http`` section; the pki folder (the server's own
certificate, the trusted and the rejected clients') must be usable before the daemon starts.
"""

from __future__ import annotations

import os
from pathlib import Path

from fcmaster.adapters.settings import modbus_listen
from fcmaster.config_sections import HttpModel, OpcuaModel, is_loopback

__all__ = ["check_opcua", "pki_problem"]


def check_opcua(
    opcua: OpcuaModel, http: HttpModel | None, pki: Path, problems: list[tuple[str, str]]
) -> None:
    """Add to ``problems`` what is wrong with ``opcua`` (``pki``: its folder, resolved)."""
    tokens = http.tokens if http is not None else []
    host, _ = modbus_listen(opcua.listen)
    if not tokens and not is_loopback(host):
        problems.append(
            (
                "opcua.listen",
                f"{opcua.listen} reaches beyond this machine and there are no users: add "
                "http.tokens (user name = token name, password = token) or listen on 127.0.0.1",
            )
        )
    if opcua.commands and "None" in opcua.security:
        problems.append(
            (
                "opcua.security",
                "the None policy sends passwords and method calls unsigned and in clear: it "
                "may not be listed while opcua.commands is true",
            )
        )
    if opcua.commands and not any(t.role == "operator" for t in tokens):
        problems.append(
            (
                "opcua.commands",
                "methods are called by operators of http.tokens, and there is none: add one",
            )
        )
    problem = pki_problem(pki)
    if problem:
        problems.append(("opcua.pki", problem))


def pki_problem(pki: Path) -> str:
    """Why the server could not keep its certificates in ``pki`` ("" when it can)."""
    if pki.exists():
        if not pki.is_dir():
            return f"{pki} is not a folder"
        if not os.access(pki, os.R_OK | os.W_OK | os.X_OK):
            return f"cannot read and write {pki}: give the daemon's user access to it"
        return ""
    parent = pki.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        return f"{pki} does not exist and cannot be created in {parent}: create it for the daemon"
    return ""
