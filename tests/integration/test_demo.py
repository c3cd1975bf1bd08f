"""`fcmaster run` with no `--config`: the demo fleet, as a newcomer starts it.

It runs from an empty directory (the demo config is package data, not a checkout file),
on a free port given with ``--http-listen`` because 8080 may be taken on a CI machine, and
is watched over its HTTP API the way the dashboard reads it: anonymously, on loopback.
"""

from __future__ import annotations

import asyncio
import fnmatch
import os
import re
import signal
import socket
import tempfile
import tomllib
from pathlib import Path
from typing import Any

import httpx
import pytest

import fcmaster
from fcmaster.cli import DEMO_CONFIG
from fcmaster.config import load
from tests.integration.daemon_harness import START_S, by_name, child, get_json, until
from tests.integration.ports import free_port


def test_the_demo_serves_loopback_8080_with_anonymous_reads() -> None:
    http = load(DEMO_CONFIG).model.http
    assert http is not None
    assert http.listen == "127.0.0.1:8080"
    assert http.anonymous == "viewer"


def test_the_files_the_demo_needs_are_package_data() -> None:
    """An installed fcmaster (a wheel, the Docker image) has no checkout to read them from."""
    root = Path(fcmaster.__file__).parent
    pyproject = tomllib.loads((root.parent / "pyproject.toml").read_text())
    globs = pyproject["tool"]["setuptools"]["package-data"]
    needed = [DEMO_CONFIG, *(p for p in (root / "adapters" / "static").rglob("*") if p.is_file())]
    assert len(needed) > 3
    for path in needed:
        package = ".".join(path.parent.relative_to(root.parent).parts[:2])
        within = path.relative_to(root.parent / package.replace(".", "/")).as_posix()
        assert any(fnmatch.fnmatch(within, g) for g in globs.get(package, [])), path


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
async def test_the_demo_shows_a_living_fleet_and_exits_0_on_a_signal(
    tmp_path: Path, signum: signal.Signals
) -> None:
    port = free_port()
    args = ("run", "--http-listen", f"127.0.0.1:{port}")
    async with (
        child(*args, log=tmp_path / "run.log", cwd=tmp_path) as demo,
        httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}", timeout=10) as anonymous,
    ):
        # It prints where the dashboard is, with an operator token for its buttons.
        banner = await demo.readline()
        match = re.fullmatch(
            rf"fcmaster demo: dashboard at http://127\.0\.0\.1:{port}/#token=(\S+)\n", banner
        )
        assert match, banner
        token = match[1]

        async def living_fleet() -> dict[str, dict[str, Any]] | None:
            drives = by_name(await get_json(anonymous, "/api/v1/drives"))
            online = [d for d in drives.values() if d["online"]]
            running = [d for d in online if d["running"]]
            return drives if len(online) >= 8 and len(running) >= 3 else None

        drives = await until(living_fleet, "living demo fleet", alive=demo)
        assert len(drives) == 10
        assert {d["bus"] for d in drives.values()} == {"line1", "line2"}
        assert drives["supply-pump-1"]["running"] is True
        assert abs(drives["supply-pump-1"]["output_frequency_hz"] - 42.0) < 1.0
        buses = by_name(await get_json(anonymous, "/api/v1/buses"))
        assert buses["line1"]["up"] is True
        assert buses["line2"]["up"] is True

        # Reads need no token; moving a motor does, and the printed one works.
        command = {"action": "start", "frequency_hz": 20}
        refused = await anonymous.post("/api/v1/drives/mixer-1/commands", json=command)
        assert refused.status_code == 401
        started = await anonymous.post(
            "/api/v1/drives/mixer-1/commands",
            json=command,
            headers={"Authorization": f"Bearer {token}"},
        )
        assert started.status_code == 200, started.text
        assert started.json()["outcome"] == "done"

        code, _ = await demo.stop(signum)
        assert code == 0, demo.tail()
        assert os.listdir(tmp_path) == ["run.log"]  # it wrote nothing in its working directory


async def test_http_listen_cannot_open_the_tokenless_demo_beyond_loopback(tmp_path: Path) -> None:
    port = free_port()
    args = ("run", "--http-listen", f"0.0.0.0:{port}")
    async with child(*args, log=tmp_path / "run.log", cwd=tmp_path) as demo:
        assert await asyncio.wait_for(demo.process.wait(), START_S) == 2
    assert "http.listen: 0.0.0.0" in demo.tail()
    assert "is not a loopback address" in demo.tail()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("run", "--http-listen", "127.0.0.1:99999"), "--http-listen: port 99999 is beyond 65535"),
        (("sim", "--bus", "north"), "--bus selects buses of a --config file"),
        (("sim", "--config", str(DEMO_CONFIG), "--bus", "north"), "has no bus called north"),
    ],
    ids=["http-listen-port", "bus-without-config", "unknown-bus"],
)
async def test_bad_options_exit_2_saying_what_is_wrong(
    tmp_path: Path, args: tuple[str, ...], message: str
) -> None:
    async with child(*args, log=tmp_path / "err.log", cwd=tmp_path) as command:
        assert await asyncio.wait_for(command.process.wait(), START_S) == 2
    assert message in command.tail()


async def test_under_systemd_it_says_ready_once_serving_and_stopping_on_sigterm() -> None:
    """Type=notify: READY=1 only when the lines are open and the API answers."""
    loop = asyncio.get_running_loop()
    port = free_port()
    # A short directory: a Unix socket path must fit in 108 bytes.
    with (
        tempfile.TemporaryDirectory(prefix="fcm-") as directory,
        socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as notify,
    ):
        notify.bind(f"{directory}/notify")
        notify.setblocking(False)
        env = {"NOTIFY_SOCKET": f"{directory}/notify"}
        args = ("run", "--http-listen", f"127.0.0.1:{port}")
        log = Path(directory) / "run.log"
        async with (
            child(*args, log=log, cwd=Path(directory), env=env) as demo,
            httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}", timeout=10) as anonymous,
        ):
            ready = await asyncio.wait_for(loop.sock_recv(notify, 512), START_S)
            assert ready == b"READY=1"
            buses = by_name(await get_json(anonymous, "/api/v1/buses"))  # no retry needed
            assert buses["line1"]["up"] is True
            assert buses["line2"]["up"] is True

            demo.process.send_signal(signal.SIGTERM)
            stopping = await asyncio.wait_for(loop.sock_recv(notify, 512), START_S)
            assert stopping == b"STOPPING=1"
            assert await asyncio.wait_for(demo.process.wait(), START_S) == 0
