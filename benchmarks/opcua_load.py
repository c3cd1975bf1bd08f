"""What OPC UA clients cost the lines: 0 vs 3 clients subscribed to every variable.

Run: ``python benchmarks/opcua_load.py [--lines 1] [--drives 126] [--baudrate 115200]
[--window 10] [--cycles 2] [--output FILE]`` (a few minutes; needs node and
``tests/node/opcua``'s packages: ``npm ci``).

``fcmaster sim`` serves ``--lines`` simulated FC lines on pseudo-terminals (115200 baud unless
``--baudrate``: at 115200 the pause has often gone by before the next request is ready, so few
timers wait and few lateness samples come; at 19200 its 2 ms are waited out by a timer) of
``--drives`` drives each, and ``fcmaster run`` polls them through the real serial path, with
the HTTP API and the OPC UA server (``commands: false``). Every drive is found running
slowly and sent towards 50 Hz on a 10-minute ramp, so every poll reads a new output
frequency, current, power: the drives change at the full rate the line reads them. The
client is node-opcua (``tests/node/opcua/client.js``), its certificate trusted first. Then
windows of ``--window`` seconds, alternately quiet and with 3 clients each holding one
subscription (100 ms publishing) to every variable of every drive (status, frequency,
alarms, each monitored value: all the drives show), ``--cycles`` times. A loaded window
starts once all 3 clients are subscribed. SCADA clients run on other machines: here they
share the gateway's cores, so they run at the lowest priority (``nice 19``) to take only
what the gateway leaves. Per window:

- each line's transactions per second (``/api/v1/buses``), and the mean gap between good
  replies of its drive that answered least often;
- its timers' wake-up lateness (``fcmaster_bus_wakeup_lateness_seconds``, the same histogram):
  the p99 as the bucket bound it falls under, the p99 of the window's raw samples
  (the window's ``lateness_p99_raw_s``, one per line: the daemon runs under
  ``lateness_tap.py``, which keeps them), and
  the mean (null: no timer of the line waited in that window, its pauses spent before the
  next request was ready);
- the OPC UA server process's CPU (share of one core) and RSS, and the daemon's CPU;
- for loaded windows, each client's notifications per second and the time it took to
  subscribe to every variable.

The machine's load average goes with the figures. Linux only (``/proc``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Final

import lateness_tap
import results_file
from daemon_footprint import _cpu_s, _free_port, _rss_kib, _wait_for_fleet

ROOT: Final = Path(__file__).resolve().parent.parent
CLIENT: Final = ROOT / "tests" / "node" / "opcua"
DEFAULT_OUTPUT: Final = Path(__file__).resolve().parent / "results" / "opcua_load.json"
TOKEN: Final = "viewer-token-0123456789abcdef"
OPERATOR: Final = "operator-token-0123456789abcdef"
RAMP_S: Final = 600  # FC 3-41: 0 to nominal in 10 minutes, so each poll reads a new speed
SUBSCRIBE_S: Final = 300.0  # three clients creating thousands of monitored items on 2 cores
STATUS: Final = (
    "Online", "Running", "Fault", "Warning", "AtReference", "Direction", "StatusWord",
    "OutputFrequency", "ReferencePercent", "Alarms", "Warnings", "WatchdogVerdict",
)  # fmt: skip


def _config(lines: int, drives: int, http: int, opcua: int, folder: Path, baud: int) -> str:
    return (
        _buses(lines, drives, folder, baud)
        + _http(http)
        + f"opcua:\n  listen: 127.0.0.1:{opcua}\n  pki: {folder / 'pki'}\n"
        + "logging: {level: info, format: json}\n"
    )


def _buses(lines: int, drives: int, folder: Path, baud: int) -> str:
    """``buses:`` of simulated lines whose drives all run on a long ramp (see the docstring)."""
    running = ", ".join(
        f"{a}: {{running_hz: {5 + a % 10}, parameters: {{'3-41': {RAMP_S}}}}}"
        for a in range(1, drives + 1)
    )
    text = "buses:\n"
    for line in range(1, lines + 1):
        text += (
            f"  - name: line{line}\n    port: {folder / f'ttyL{line}'}\n    baudrate: {baud}\n"
            f"    simulation: {{drives: {{{running}}}}}\n    drives:\n"
        )
        text += "".join(
            f"      - {{name: l{line}d{a}, address: {a}, control: bus}}\n"
            for a in range(1, drives + 1)
        )
    return text


def _http(http: int) -> str:
    """``http:`` on port ``http``, with a viewer's and an operator's token."""
    return (
        f"http:\n  listen: 127.0.0.1:{http}\n  anonymous: viewer\n  tokens:\n"
        f"    - {{name: scada, role: viewer, token: {TOKEN}}}\n"
        f"    - {{name: ops, role: operator, token: {OPERATOR}}}\n"
    )


def _get(url: str) -> Any:
    with urllib.request.urlopen(url, timeout=30) as response:
        return json.load(response)


def _plan(folder: Path, url: str, steps: list[dict[str, Any]]) -> Path:
    file = folder / f"plan-{len(list(folder.glob('plan-*')))}.json"
    plan = {"url": url, "pki": str(folder / "client-pki"), "user": "scada", "password": TOKEN}
    file.write_text(json.dumps({**plan, "steps": steps}))
    return file


def _node(plan: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        ["nice", "-n", "19", "node", str(CLIENT / "client.js"), str(plan)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=CLIENT,
    )  # fmt: skip


def _result(process: subprocess.Popen[str]) -> dict[str, Any]:
    out, err = process.communicate(timeout=SUBSCRIBE_S)
    lines = [line for line in out.splitlines() if line.startswith("{")]
    if not lines:
        raise SystemExit(f"the OPC UA client printed no result:\n{out}\n{err}")
    result: dict[str, Any] = json.loads(lines[-1])
    return result


def _trust_client(folder: Path, url: str, pki: Path) -> None:
    sys.path.insert(0, str(ROOT))
    from fcmaster.opcua import pki as pki_module

    deadline = time.monotonic() + 60
    while True:  # the server takes a while to build its address space
        first = _result(_node(_plan(folder, url, [{"op": "browse", "node": "ns=2;s=Drives"}])))
        if "BadCertificateUntrusted" in first.get("error", ""):
            break
        if time.monotonic() > deadline:
            raise SystemExit(f"the OPC UA server did not refuse the client: {first}")
        threading.Event().wait(1)
    (rejected,) = pki_module.certificates(pki)["rejected"]
    pki_module.trust(pki, rejected["thumbprint"])


def _ramp_all(base: str) -> None:
    """Send every drive towards 50 Hz: on its long ramp, each poll reads a new speed."""

    def ramp(name: str) -> str:
        request = urllib.request.Request(
            f"{base}/api/v1/drives/{name}/commands",
            data=json.dumps({"action": "set_reference", "frequency_hz": 50}).encode(),
            headers={"Authorization": f"Bearer {OPERATOR}", "Content-Type": "application/json"},
        )
        with urllib.request.urlopen(request, timeout=120) as response:
            outcome: str = json.load(response)["outcome"]
            return outcome

    names = [drive["name"] for drive in _get(f"{base}/api/v1/drives")]
    with ThreadPoolExecutor(max_workers=32) as pool:
        outcomes = list(pool.map(ramp, names))
    if set(outcomes) != {"done"}:
        raise SystemExit(f"not every drive took its reference: {outcomes}")


def _lines(base: str) -> dict[str, dict[str, Any]]:
    out = {}
    for bus in _get(f"{base}/api/v1/buses"):
        stats = bus["stats"]
        lateness = stats["wakeup_lateness_s"]
        out[bus["name"]] = {
            "requests": stats["requests"],
            "drives": {name: d["replies"] for name, d in stats["drives"].items()},
            "buckets": [(b["le"], b["count"]) for b in lateness["buckets"]],
            "count": lateness["count"],
            "sum": lateness["sum"],
        }
    return out


def _p99(before: list[tuple[float, int]], after: list[tuple[float, int]]) -> float | None:
    counts = [(le, b - a) for (le, b), (_, a) in zip(after, before, strict=True)]
    total = counts[-1][1]
    if not total:
        return None
    for le, cumulative in counts:
        if cumulative >= 0.99 * total:
            return float(le)
    return None


def line_figures(
    before: dict[str, dict[str, Any]], after: dict[str, dict[str, Any]], took: float
) -> dict[str, dict[str, Any]]:
    """Each line's figures between two reads of ``_lines`` ``took`` seconds apart."""
    lines = {}
    for name, end in after.items():
        start = before[name]
        count = end["count"] - start["count"]
        polls = [end["drives"][d] - start["drives"].get(d, 0) for d in end["drives"]]
        lines[name] = {
            "rate_per_s": (end["requests"] - start["requests"]) / took,
            # the drive answered least often: its mean gap between good replies
            "slowest_drive_gap_s": took / min(polls) if polls and min(polls) else None,
            "lateness_p99_s": _p99(start["buckets"], end["buckets"]),
            "lateness_mean_s": (end["sum"] - start["sum"]) / count if count else None,
        }
    return lines


def _window(
    base: str, seconds: float, daemon_pid: int, server_pid: int, pause: threading.Event
) -> dict[str, Any]:
    before, t0 = _lines(base), time.monotonic()
    cpu0, server_cpu0 = _cpu_s(daemon_pid), _cpu_s(server_pid)
    pause.wait(seconds)
    after, took = _lines(base), time.monotonic() - t0
    cpu1, server_cpu1 = _cpu_s(daemon_pid), _cpu_s(server_pid)
    return {
        "seconds": took,
        "span": (t0, t0 + took),
        "lines": line_figures(before, after, took),
        "daemon_cpu": (cpu1 - cpu0) / took,
        "server_cpu": (server_cpu1 - server_cpu0) / took,
        "server_rss_kib": _rss_kib(server_pid)[0],
        "load_average": os.getloadavg(),
    }


def _server_pid(log: Path) -> int:
    pids = [json.loads(line).get("pid") for line in log.read_text().splitlines()
            if '"opcua.server_started"' in line]  # fmt: skip
    return int(pids[-1])


def _variables(base: str) -> list[str]:
    nodes = []
    for drive in _get(f"{base}/api/v1/drives"):
        nodes += [f"ns=2;s=Drives/{drive['name']}/{v}" for v in STATUS]
        names = [v["name"] or p for p, v in drive["values"].items()]
        nodes += [f"ns=2;s=Drives/{drive['name']}/Values/{n}" for n in names]
    return nodes


def _loaded(
    folder: Path, url: str, base: str, args: argparse.Namespace, pids: tuple[int, int],
    pause: threading.Event,
) -> dict[str, Any]:  # fmt: skip
    nodes = _variables(base)
    seconds = SUBSCRIBE_S  # counted by each client from its subscription on; stopped below
    plan = _plan(folder, url, [{"op": "count", "nodes": nodes, "seconds": args.window + 5}])
    clients = [_node(plan) for _ in range(3)]
    subscribed = []
    deadline = time.monotonic() + seconds
    for client in clients:
        assert client.stderr is not None
        while time.monotonic() < deadline:
            line = client.stderr.readline()
            if not line:
                raise SystemExit(f"a client ended before it subscribed: {_result(client)}")
            if line.startswith("subscribed "):
                subscribed.append(int(line.split()[1]) / 1000)
                break
    window = _window(base, args.window, *pids, pause)
    results = [_result(client) for client in clients]
    window["clients"] = {
        "variables": len(nodes),
        "subscribe_s": subscribed,
        "notifications_per_s": [r["steps"][0].get("per_s") for r in results],
    }
    return window


@contextlib.contextmanager
def plant(
    config: Path, lines: int, base: str, pause: threading.Event
) -> Iterator[subprocess.Popen[bytes]]:
    """``fcmaster sim`` serving ``config``'s lines and ``fcmaster run`` polling them.

    The daemon runs under ``lateness_tap.py`` (its samples in ``lateness.json`` beside
    ``config``, its log in ``run.log``); yielded once every drive is online (``base``: its
    HTTP API). Both are stopped at the end.
    """
    folder = config.parent
    sim = subprocess.Popen(
        [sys.executable, "-m", "fcmaster", "sim", "--config", str(config)],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT,
    )  # fmt: skip
    assert sim.stdout is not None
    for _ in range(lines):  # `BUS PATH` per line once its pty is linked
        sim.stdout.readline()
    with (folder / "run.log").open("wb") as stderr:
        daemon = subprocess.Popen(
            [sys.executable, str(Path(__file__).parent / "lateness_tap.py"),
             str(folder / "lateness.json"), "run", "--config", str(config)],
            stdout=subprocess.DEVNULL, stderr=stderr, cwd=ROOT,
        )  # fmt: skip
    try:
        _wait_for_fleet(base, daemon, pause)
        yield daemon
    finally:
        daemon.terminate()
        daemon.wait(timeout=30)
        sim.terminate()
        sim.wait(timeout=30)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lines", type=int, default=1)
    parser.add_argument("--drives", type=int, default=126)
    parser.add_argument("--baudrate", type=int, default=115200)
    parser.add_argument("--window", type=float, default=10.0)
    parser.add_argument("--cycles", type=int, default=2)
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    args = parser.parse_args()
    pause = threading.Event()
    with tempfile.TemporaryDirectory() as temp:
        folder = Path(temp)
        http, opcua = _free_port(), _free_port()
        config = folder / "plant.yaml"
        config.write_text(_config(args.lines, args.drives, http, opcua, folder, args.baudrate))
        log, samples = folder / "run.log", folder / "lateness.json"
        base, url = f"http://127.0.0.1:{http}", f"opc.tcp://127.0.0.1:{opcua}/"
        with plant(config, args.lines, base, pause) as daemon:
            _trust_client(folder, url, folder / "pki")
            pids = (daemon.pid, _server_pid(log))
            _ramp_all(base)
            pause.wait(5)  # the values of every drive read once (they name the variables)
            windows = []
            for cycle in range(args.cycles):
                quiet = _window(base, args.window, *pids, pause)
                windows.append({"cycle": cycle, "clients": 0, **quiet})
                loaded = _loaded(folder, url, base, args, pids, pause)
                windows.append({"cycle": cycle, **loaded})
                print(json.dumps(windows[-2:], default=str)[:600], flush=True)
        raw = lateness_tap.load(samples)
    for window in windows:  # each line's p99 of the window's own samples (lines unnamed)
        start, end = window.pop("span")
        window["lateness_p99_raw_s"] = [lateness_tap.p99(s, start, end) for s in raw.values()]
        window["lateness_samples"] = [sum(start <= t < end for t, _ in s) for s in raw.values()]
    quiet_w = [w for w in windows if w["clients"] == 0]
    loaded_w = [w for w in windows if w["clients"] != 0]

    def mean(items: list[float | None]) -> float | None:
        given = [i for i in items if i is not None]
        return sum(given) / len(given) if given else None

    def worst(ws: list[dict[str, Any]], key: str) -> float | None:
        given = [line[key] for w in ws for line in w["lines"].values() if line[key] is not None]
        return max(given, default=None)

    def worst_raw(ws: list[dict[str, Any]]) -> float | None:
        given = [p for w in ws for p in w["lateness_p99_raw_s"] if p is not None]
        return max(given, default=None)

    def per_line(ws: list[dict[str, Any]], key: str) -> float | None:
        return mean([line[key] for w in ws for line in w["lines"].values()])

    summary = {
        "rate_quiet_per_s": per_line(quiet_w, "rate_per_s"),
        "rate_loaded_per_s": per_line(loaded_w, "rate_per_s"),
        "slowest_drive_gap_quiet_s": worst(quiet_w, "slowest_drive_gap_s"),
        "slowest_drive_gap_loaded_s": worst(loaded_w, "slowest_drive_gap_s"),
        "lateness_p99_quiet_s": worst(quiet_w, "lateness_p99_s"),
        "lateness_p99_loaded_s": worst(loaded_w, "lateness_p99_s"),
        "lateness_p99_raw_quiet_s": worst_raw(quiet_w),
        "lateness_p99_raw_loaded_s": worst_raw(loaded_w),
        "lateness_mean_quiet_s": per_line(quiet_w, "lateness_mean_s"),
        "lateness_mean_loaded_s": per_line(loaded_w, "lateness_mean_s"),
        "server_cpu_quiet": mean([w["server_cpu"] for w in quiet_w]),
        "server_cpu_loaded": mean([w["server_cpu"] for w in loaded_w]),
        "server_rss_kib": max(w["server_rss_kib"] for w in windows),
        "subscribe_every_variable_s": max(s for w in loaded_w for s in w["clients"]["subscribe_s"]),
        "variables": loaded_w[0]["clients"]["variables"],
    }
    rate_q, rate_l = summary["rate_quiet_per_s"], summary["rate_loaded_per_s"]
    summary["rate_loaded_vs_quiet"] = rate_l / rate_q if rate_q and rate_l else None
    results = {
        **results_file.provenance("opcua_load"),
        "lines": args.lines,
        "drives_per_line": args.drives,
        "baudrate": args.baudrate,
        "window_s": args.window,
        "summary": summary,
        "windows": windows,
    }
    results_file.write(args.output, results)
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
