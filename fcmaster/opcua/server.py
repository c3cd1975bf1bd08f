"""The OPC UA server process: ``python -m fcmaster.opcua.server --fd N``.

Theory of operation
-------------------
The daemon starts this process with one end of a Unix socket pair as file descriptor ``N``
(see :mod:`fcmaster.adapters.opcua`). Its work, and its garbage, live here, apart from the
lines' event loop: a client that subscribes to every variable costs this process CPU, never a
line's timing. It reads the ``hello`` (settings, users, drives, lines), makes its certificate
on the first start, builds the address space, listens, says ``ready``, and then shows each
``drives`` and ``lines`` message as it comes. A method call is sent to the daemon as a
``call`` with the session's user, and answered once the daemon's ``result`` (the command's
outcome) arrives. When the pipe closes (the daemon stopped or died) the process ends.

It runs at a lower priority than the daemon (:data:`NICENESS`), so where the gateway's cores
are busy the lines go first. Endpoints are only those of ``opcua.security``; users are
``http.tokens``; anonymous only when switched on (:mod:`.access`).
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import logging
import os
import socket
import sys
from pathlib import Path
from typing import Any, Final

import structlog
from asyncua import Server, ua

from fcmaster import logsetup
from fcmaster.opcua import limits, pki
from fcmaster.opcua.access import CALLER, Channels, Gate, Rules, Users, track_callers
from fcmaster.opcua.sessions import SessionBook
from fcmaster.opcua.space import Space
from fcmaster.opcua.wire import Decoder, encode

log = structlog.get_logger("fcmaster.opcua")

NICENESS: Final = 10  # added to the daemon's: this process yields the cores to the lines

_POLICIES: Final = {
    "None": ua.SecurityPolicyType.NoSecurity,
    "Basic256Sha256:Sign": ua.SecurityPolicyType.Basic256Sha256_Sign,
    "Basic256Sha256:SignAndEncrypt": ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
    "Aes128_Sha256_RsaOaep:Sign": ua.SecurityPolicyType.Aes128Sha256RsaOaep_Sign,
    "Aes128_Sha256_RsaOaep:SignAndEncrypt": (
        ua.SecurityPolicyType.Aes128Sha256RsaOaep_SignAndEncrypt
    ),
    "Aes256_Sha256_RsaPss:Sign": ua.SecurityPolicyType.Aes256Sha256RsaPss_Sign,
    "Aes256_Sha256_RsaPss:SignAndEncrypt": ua.SecurityPolicyType.Aes256Sha256RsaPss_SignAndEncrypt,
}


class _Library(logging.Handler):
    """asyncua's own warnings, as the daemon's structured log lines."""

    def emit(self, record: logging.LogRecord) -> None:
        log.warning("opcua.library_said", logger=record.name, message=record.getMessage())


class Child:
    """One server, fed by the daemon through ``writer``/``reader``."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader = reader
        self.writer = writer
        self.decoder = Decoder()
        self._pending: list[dict[str, Any]] = []  # decoded, not yet taken
        self._calls: dict[int, asyncio.Future[dict[str, Any]]] = {}
        self._ids = itertools.count(1)

    def send(self, message: dict[str, Any]) -> None:
        """Write ``message`` to the daemon (the socket buffers; the daemon reads at once)."""
        self.writer.write(encode(message))

    async def next_message(self) -> dict[str, Any] | None:
        """The next message from the daemon; None once the pipe closed."""
        while not self._pending:
            data = await self.reader.read(65536)
            if not data:
                return None
            self._pending.extend(self.decoder.feed(data))
        return self._pending.pop(0)

    async def call(self, drive: str, method: str, command: dict[str, Any]) -> Any:
        """A method call: sent to the daemon, answered with the command's outcome."""
        user = CALLER.get()
        if user is None:  # the session could not be established: never guess
            return ua.StatusCode(ua.StatusCodes.BadUserAccessDenied)
        number = next(self._ids)
        future: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()
        self._calls[number] = future
        try:  # whatever happens (the send fails too), the call leaves no future behind
            self.send({"t": "call", "id": number, "drive": drive, "user": user.name,
                       "method": method, "command": command})  # fmt: skip
            result = await future
        finally:
            self._calls.pop(number, None)
        if result.get("denied"):
            return ua.StatusCode(ua.StatusCodes.BadUserAccessDenied)
        return [
            ua.Variant(str(result["outcome"]), ua.VariantType.String),
            ua.Variant(str(result.get("reason", "")), ua.VariantType.String),
        ]

    def answered(self, message: dict[str, Any]) -> None:
        """A ``result`` from the daemon ends its call."""
        future = self._calls.get(int(message["id"]))
        if future is not None and not future.done():
            future.set_result(message)

    def rejected(self, print_: str, uri: str) -> None:
        """A client certificate was refused: say so, once per attempt."""
        log.warning("opcua.certificate_rejected", thumbprint=print_, application_uri=uri)


async def serve(child: Child, hello: dict[str, Any]) -> None:
    """Build the server from ``hello`` and serve until the pipe closes."""
    settings = hello["settings"]
    folder = Path(settings["pki"])
    host, port = settings["host"], settings["port"]
    cert, key = pki.own_certificate(folder, (host,))
    users = Users(dict(settings["users"]), anonymous=settings["anonymous"])
    server = Server(user_manager=users)
    await server.init()
    book = SessionBook(server, lambda listed: child.send({"t": "sessions", "sessions": listed}))
    rules = Rules(anonymous=settings["anonymous"])
    policies = [_POLICIES[s] for s in settings["security"]]
    channels = Channels(server, list(settings["security"]), rules)
    track_callers(server.iserver, book, channels, limits.SessionQuota(server))
    server.set_endpoint(f"opc.tcp://{'[' + host + ']' if ':' in host else host}:{port}/")
    server.set_server_name("fcmaster")
    await server.set_application_uri(pki.APPLICATION_URI)
    server.product_uri = "urn:fcmaster"
    server.manufacturer_name = "fcmaster"
    server.application_type = ua.ApplicationType.Server
    await server.load_certificate(str(cert))
    await server.load_private_key(str(key))
    server.set_security_policy(policies, permission_ruleset=rules)
    tokens: list[type] = [ua.UserNameIdentityToken]
    if settings["anonymous"]:
        tokens.append(ua.AnonymousIdentityToken)
    server.set_identity_tokens(tokens)
    server.set_certificate_validator(Gate(folder, child.rejected))
    space = Space(server, child.call)
    await space.build(hello["drives"], hello["lines"])
    limits.apply(server)
    async with server:
        limits.apply(server)
        channels.limit_none(policies)
        child.send({"t": "ready"})
        log.info("opcua.listening", host=host, port=port, security=settings["security"])
        while (message := await child.next_message()) is not None:
            kind = message["t"]
            if kind == "drives":
                for entry in message["drives"]:
                    await space.update_drive(entry)
            elif kind == "lines":
                for line in message["lines"]:
                    await space.update_line(line)
            elif kind == "result":
                child.answered(message)


async def main(fd: int) -> int:
    """Serve over the socket ``fd``; 0 when the daemon closed the pipe, 1 when serving failed.

    Whatever happens is logged as the daemon logs (JSON lines on the shared stderr), never
    as a bare traceback.
    """
    logsetup.configure("info", "json")
    sock = socket.socket(fileno=fd)
    reader, writer = await asyncio.open_unix_connection(sock=sock)
    child = Child(reader, writer)
    try:
        hello = await child.next_message()
        if hello is None or hello.get("t") != "hello":
            log.error("opcua.server_failed", reason="the daemon sent no hello")
            return 1
        logsetup.configure(hello["settings"].get("log_level", "info"), "json")
        library = logging.getLogger("asyncua")
        library.setLevel(logging.WARNING)
        library.addHandler(_Library())
        library.propagate = False
        await serve(child, hello)
    except OSError as exc:  # the port is taken, the pki unwritable: the daemon retries
        log.error("opcua.server_failed", reason=f"{exc.strerror or exc}")
        return 1
    except Exception:  # a bug: said in the log, and the daemon starts a new server
        log.exception("opcua.server_failed")
        return 1
    return 0


def run() -> None:
    """The process's entry point."""
    # Where the gateway's cores are busy, the lines' process goes first: a late notification
    # costs a SCADA screen a moment, a late telegram costs a drive its watchdog.
    os.nice(NICENESS)
    parser = argparse.ArgumentParser(prog="python -m fcmaster.opcua.server")
    parser.add_argument("--fd", type=int, required=True, help="the daemon's socket")
    args = parser.parse_args()
    try:
        sys.exit(asyncio.run(main(args.fd)))
    except KeyboardInterrupt:  # the daemon's terminal was interrupted: the daemon decides
        sys.exit(130)


if __name__ == "__main__":
    run()
