"""The OPC UA server's certificates: its own, the clients' it trusts and those it rejected.

Layout under the ``opcua.pki`` folder (created on the first start, owner only)::

    own/cert.der  own/key.pem     the server's certificate (made on the first start)
    trusted/<thumbprint>.der      clients an operator trusted (`fcmaster opcua trust`)
    rejected/<thumbprint>.der     clients that tried to connect and were refused

A thumbprint is the SHA-1 of the certificate's DER bytes, in hex, as UaExpert and most OPC
UA tools show it. Only the trusted folder decides: a certificate is trusted while its file
is there, so trusting one or taking the trust away needs no restart.
"""

from __future__ import annotations

import datetime
import hashlib
import os
import socket
import time
from pathlib import Path
from typing import Any, Final

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import rsa
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from fcmaster.errors import UsageError

__all__ = [
    "APPLICATION_URI",
    "FOLDERS",
    "certificates",
    "own_certificate",
    "reject",
    "thumbprint",
    "trust",
    "trusted",
]

APPLICATION_URI: Final = f"urn:{socket.gethostname()}:fcmaster"
FOLDERS: Final = ("own", "trusted", "rejected")
KEEP_REJECTED: Final = 100  # a client flooding new certificates must not fill the disk
_VALID_DAYS: Final = 3650
_KEY_BITS: Final = 2048  # what Basic256Sha256 and Aes256_Sha256_RsaPss ask for (2048-4096)


def thumbprint(der: bytes) -> str:
    """The SHA-1 of a certificate's DER bytes, lower-case hex."""
    return hashlib.sha1(der, usedforsecurity=False).hexdigest()


def _folders(pki: Path) -> None:
    for name in FOLDERS:
        (pki / name).mkdir(mode=0o700, parents=True, exist_ok=True)


def own_certificate(pki: Path, hostnames: tuple[str, ...] = ()) -> tuple[Path, Path]:
    """The server's certificate and key files, made on the first call (self-signed, RSA 2048).

    ``hostnames`` go into the certificate with this machine's name, so that clients which
    check the host they connect to find it there.
    """
    _folders(pki)
    cert_file, key_file = pki / "own" / "cert.der", pki / "own" / "key.pem"
    if cert_file.exists() and key_file.exists():
        return cert_file, key_file
    key = rsa.generate_private_key(public_exponent=65537, key_size=_KEY_BITS)
    name = x509.Name(
        [
            x509.NameAttribute(NameOID.COMMON_NAME, f"fcmaster@{socket.gethostname()}"),
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "fcmaster"),
        ]
    )
    names = dict.fromkeys((socket.gethostname(), "localhost", *hostnames))
    now = datetime.datetime.now(datetime.UTC)
    certificate = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(days=1))
        .not_valid_after(now + datetime.timedelta(days=_VALID_DAYS))
        .add_extension(
            x509.SubjectAlternativeName(
                [x509.UniformResourceIdentifier(APPLICATION_URI)]
                + [x509.DNSName(n) for n in names if n]
            ),
            critical=False,
        )
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=True,
                key_encipherment=True,
                data_encipherment=True,
                key_agreement=False,
                key_cert_sign=True,
                crl_sign=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    pem = key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.TraditionalOpenSSL,
        serialization.NoEncryption(),
    )
    descriptor = os.open(key_file, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(descriptor, "wb") as out:
        out.write(pem)
    cert_file.write_bytes(certificate.public_bytes(serialization.Encoding.DER))
    return cert_file, key_file


def trusted(pki: Path, der: bytes) -> bool:
    """Whether the certificate ``der`` is trusted (its file is in ``trusted/``)."""
    file = pki / "trusted" / f"{thumbprint(der)}.der"
    return file.is_file() and file.read_bytes() == der


def reject(pki: Path, der: bytes, keep: int = KEEP_REJECTED) -> Path:
    """Keep a refused client's certificate in ``rejected/`` for an operator to judge.

    Only the ``keep`` refused last are kept: the oldest files go. A certificate refused
    again counts as new, so the client an operator is about to trust stays.
    """
    _folders(pki)
    file = pki / "rejected" / f"{thumbprint(der)}.der"
    if not file.exists():
        file.write_bytes(der)
    others = [f for f in (pki / "rejected").glob("*.der") if f != file]
    kept = sorted(others, key=lambda f: f.stat().st_mtime_ns)
    # its time says it is the newest even where the clock ticks coarser than refusals come
    newest = max([time.time_ns(), *(f.stat().st_mtime_ns + 1 for f in kept[-1:])])
    os.utime(file, ns=(newest, newest))
    for old in kept[: max(0, len(kept) + 1 - keep)]:
        old.unlink(missing_ok=True)
    return file


def trust(pki: Path, print_: str) -> Path:
    """Move the rejected certificate whose thumbprint is ``print_`` to ``trusted/``.

    UsageError when none has it (with the thumbprints there are).
    """
    wanted = print_.lower().replace(":", "").replace(" ", "")
    rejected = sorted((pki / "rejected").glob("*.der")) if (pki / "rejected").is_dir() else []
    for file in rejected:
        der = file.read_bytes()
        if thumbprint(der) == wanted:
            _folders(pki)
            target = pki / "trusted" / file.name
            target.write_bytes(der)
            file.unlink()
            return target
    if (pki / "trusted" / f"{wanted}.der").is_file():
        raise UsageError(f"{print_} is trusted already")
    known = ", ".join(thumbprint(f.read_bytes()) for f in rejected) or "none"
    raise UsageError(f"no rejected certificate has thumbprint {print_} (rejected: {known})")


def certificates(pki: Path) -> dict[str, list[dict[str, Any]]]:
    """Every certificate by folder: ``thumbprint``, ``subject``, ``file``."""
    out: dict[str, list[dict[str, Any]]] = {}
    for name in FOLDERS:
        folder = pki / name
        files = sorted(folder.glob("*.der")) if folder.is_dir() else []
        out[name] = [_described(file) for file in files]
    return out


def _described(file: Path) -> dict[str, Any]:
    der = file.read_bytes()
    try:
        subject = x509.load_der_x509_certificate(der).subject.rfc4514_string()
    except ValueError:
        subject = "(not a certificate)"
    return {"thumbprint": thumbprint(der), "subject": subject, "file": str(file)}
