"""`fcmaster opcua certs` and `fcmaster opcua trust`: the OPC UA server's certificates.

A client's certificate is refused until an operator trusts it: the server files it in
``pki/rejected/``, ``certs`` shows it with its thumbprint (compare it with the one the client
shows), and ``trust`` moves it to ``pki/trusted/``. The running server reads the trusted
folder at each connection, so no restart is needed.
"""

from __future__ import annotations

import json
from pathlib import Path

from fcmaster import config as config_module
from fcmaster.errors import UsageError
from fcmaster.opcua import pki


def _pki(path: Path) -> Path:
    # The folder needs the opcua section only, never the tokens' values.
    settings = config_module.load(path, buses_only=True).opcua
    if settings is None:
        raise UsageError(f"{path} has no opcua section: the OPC UA server is off")
    return Path(settings.pki)


def certs(path: Path, *, as_json: bool) -> int:
    """Print the own, trusted and rejected certificates of ``path``'s server."""
    folder = _pki(path)
    found = pki.certificates(folder)
    if as_json:
        print(json.dumps(found, indent=2, ensure_ascii=False))
        return 0
    print(f"pki: {folder}")
    for kind, listed in found.items():
        print(f"{kind}:" if listed else f"{kind}: none")
        for cert in listed:
            print(f"  {cert['thumbprint']}  {cert['subject']}")
    if found["rejected"]:
        print("trust a client with: fcmaster opcua trust --config FILE THUMBPRINT")
    return 0


def trust(path: Path, thumbprint: str) -> int:
    """Trust the rejected client certificate ``thumbprint`` (UsageError: none has it)."""
    target = pki.trust(_pki(path), thumbprint)
    print(f"trusted {target.stem}: clients with this certificate may connect now")
    return 0
