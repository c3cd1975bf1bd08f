"""Memory and CPU of `fcmaster run` on the demo fleet, or on a fleet of serial lines.

Run: ``python benchmarks/daemon_footprint.py [--duration 60] [--fleet LINES,DRIVES,BAUD]
[--output FILE]``.

Without ``--fleet``, the demo (``fcmaster run`` with no ``--config``: two simulated lines,
ten drives, HTTP API and /metrics) runs as a subprocess from an empty directory, on a free
port given with ``--http-listen``. With ``--fleet 8,126,115200``, LINES simulators (``fcmaster
sim``, each in a process of its own, DRIVES FC drives with their factory response delay)
serve one pty each, and the daemon runs a config with one bus per pty (monitor-only drives,
the default monitor list, no adapters but HTTP): the gateway with several lines. Once it
shows its drives over HTTP, its resident set size (VmRSS) and
CPU time (utime + stime) are read from ``/proc/PID`` once a second for ``--duration``
seconds; the lines' request counters are read from ``/api/v1/buses`` at the start and the
end of that window, and nothing else talks to the daemon meanwhile. Then it is stopped with
SIGTERM and must exit 0.

Reported: peak and final RSS, RSS growth over the second half of the window (end minus
middle, and the least-squares slope, which a leak shows and allocator noise does not),
mean CPU as a share of one core, and transactions per second on each line. The machine's
load average goes with the figures: they mean little on a machine that is busy elsewhere.
Linux only (``/proc``).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any, Final

import results_file

DEFAULT_OUTPUT: Final = Path(__file__).resolve().parent / "results" / "daemon_footprint.json"
START_S: Final = 60.0  # the demo must show its drives within this
EXIT_S: Final = 10.0
_TICK_S: Final = os.sysconf("SC_CLK_TCK")


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def _get_json(url: str) -> Any:
    with urllib.request.urlopen(url, timeout=10) as response:
        return json.load(response)


def _rss_kib(pid: int) -> tuple[int, int, int]:
    """VmRSS, VmHWM (the kernel's peak) in KiB and the thread count of ``pid``."""
    fields: dict[str, str] = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        fields[key] = value.strip()
    return int(fields["VmRSS"].split()[0]), int(fields["VmHWM"].split()[0]), int(fields["Threads"])


def _cpu_s(pid: int) -> float:
    """utime + stime of ``pid``, in seconds."""
    stat = Path(f"/proc/{pid}/stat").read_text()
    after_name = stat.rpartition(")")[2].split()
    utime, stime = int(after_name[11]), int(after_name[12])  # fields 14 and 15 of stat(5)
    return (utime + stime) / _TICK_S


def _requests(base: str) -> dict[str, dict[str, int]]:
    return {
        line["name"]: {k: line["stats"][k] for k in ("requests", "replies", "timeouts")}
        for line in _get_json(f"{base}/api/v1/buses")
    }


def _wait_for_fleet(base: str, process: subprocess.Popen[bytes], pause: threading.Event) -> None:
    deadline = time.monotonic() + START_S
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise SystemExit(f"fcmaster run exited with {process.returncode} before it was up")
        try:
            drives = _get_json(f"{base}/api/v1/drives")
            if drives and sum(d["online"] for d in drives) >= len(drives) - 1:
                return
        except (urllib.error.URLError, ConnectionError, json.JSONDecodeError):
            pass
        pause.wait(0.1)
    raise SystemExit(f"the demo showed no drives within {START_S} s")


def _slope_per_min(points: list[tuple[float, float]]) -> float:
    """Least-squares slope of (seconds, value) points, per minute."""
    n = len(points)
    if n < 2:
        return float("nan")
    mean_t = sum(t for t, _ in points) / n
    mean_v = sum(v for _, v in points) / n
    var = sum((t - mean_t) ** 2 for t, _ in points)
    cov = sum((t - mean_t) * (v - mean_v) for t, v in points)
    return cov / var * 60.0 if var else float("nan")


def _fleet_config(cwd: Path, lines: int, drives: int, baudrate: int) -> list[str]:
    """Start one simulator per line; the daemon's arguments for a config of those lines."""
    buses = []
    for n in range(1, lines + 1):
        buses.append(
            f"  - name: line{n}\n    port: {cwd}/line{n}\n    protocol: danfoss-fc\n"
            f"    baudrate: {baudrate}\n    drives:\n"
            + "".join(f"      - {{name: l{n}d{a}, address: {a}}}\n" for a in range(1, drives + 1))
        )
    config = cwd / "fleet.yaml"
    config.write_text("buses:\n" + "".join(buses) + "http:\n  anonymous: viewer\n")
    return ["--config", str(config)]


def _start_simulators(cwd: Path, lines: int, drives: int, baudrate: int) -> list[Any]:
    sims = []
    for n in range(1, lines + 1):
        command = [sys.executable, "-m", "fcmaster", "sim", "--protocol", "danfoss-fc"]
        command += ["--addresses", f"1-{drives}", "--baudrate", str(baudrate)]
        command += ["--name", f"line{n}", "--link", str(cwd / f"line{n}")]
        sims.append(
            subprocess.Popen(
                command,
                cwd=cwd,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
        )
    deadline = time.monotonic() + START_S
    while not all((cwd / f"line{n}").exists() for n in range(1, lines + 1)):
        if time.monotonic() > deadline:
            raise SystemExit("the simulators did not show their ptys")
        threading.Event().wait(0.05)
    return sims


def measure(
    duration_s: float, interval_s: float, fleet: tuple[int, int, int] | None = None
) -> dict[str, Any]:
    """Run the daemon, sample it, stop it; the figures."""
    port = _free_port()
    base = f"http://127.0.0.1:{port}"
    pause = threading.Event()  # never set: its wait() is a sleep that ruff's ban allows
    sims: list[Any] = []
    with tempfile.TemporaryDirectory(prefix="fcmaster-footprint-") as cwd:
        log_path = Path(cwd) / "run.log"
        extra: list[str] = []
        if fleet is not None:
            sims = _start_simulators(Path(cwd), *fleet)
            extra = _fleet_config(Path(cwd), *fleet)
        with log_path.open("wb") as log:
            started = time.monotonic()
            process = subprocess.Popen(
                [sys.executable, "-m", "fcmaster", "run", "--http-listen", f"127.0.0.1:{port}",
                 *extra],
                cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=log,
            )  # fmt: skip
        try:
            _wait_for_fleet(base, process, pause)
            startup_s = time.monotonic() - started
            startup_cpu_s = _cpu_s(process.pid)
            counts_start = _requests(base)
            window_start = time.monotonic()
            samples: list[tuple[float, int, float, int]] = []
            hwm = 0
            for i in range(int(duration_s / interval_s) + 1):
                pause.wait(max(0.0, window_start + i * interval_s - time.monotonic()))
                rss_kib, hwm, threads = _rss_kib(process.pid)
                at = time.monotonic() - window_start
                samples.append((at, rss_kib, _cpu_s(process.pid), threads))
            counts_end = _requests(base)
            window_s = samples[-1][0]
            stop_at = time.monotonic()
            process.send_signal(signal.SIGTERM)
            exit_code = process.wait(EXIT_S)
            stop_s = time.monotonic() - stop_at
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
            for sim in sims:
                sim.terminate()
                sim.wait(EXIT_S)
        log_tail = log_path.read_text(errors="replace").splitlines()[-3:]

    mib = 1 / 1024
    rss = [(t, r * mib) for t, r, _, _ in samples]
    half = [(t, r) for t, r in rss if t >= window_s / 2]
    cpu_s = samples[-1][2] - samples[0][2]
    lines = {
        name: {
            "transactions_per_s": (counts_end[name]["requests"] - c["requests"]) / window_s,
            "timeouts": counts_end[name]["timeouts"] - c["timeouts"],
        }
        for name, c in counts_start.items()
    }
    return {
        "startup_s": startup_s,
        "startup_cpu_s": startup_cpu_s,
        "window_s": window_s,
        "rss_mib": {
            "start": rss[0][1],
            "peak": max(r for _, r in rss),
            "final": rss[-1][1],
            "kernel_peak_hwm": hwm * mib,
            "growth_last_half": half[-1][1] - half[0][1],
            "slope_last_half_per_min": _slope_per_min(half),
        },
        "cpu": {
            "seconds": cpu_s,
            "mean_pct_of_one_core": cpu_s / window_s * 100.0,
            "s_per_1000_transactions": cpu_s
            / max(1.0, sum(ln["transactions_per_s"] for ln in lines.values()) * window_s)
            * 1000,
        },
        "threads": samples[-1][3],
        "transactions_per_s": sum(line["transactions_per_s"] for line in lines.values()),
        "lines": lines,
        "exit_code": exit_code,
        "stop_s": stop_s,
        "log_tail": log_tail,
        "samples": [
            {"t_s": round(t, 3), "rss_kib": r, "cpu_s": round(c, 3)} for t, r, c, _ in samples
        ],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=60.0, help="seconds to sample")
    parser.add_argument("--interval", type=float, default=1.0, help="seconds between samples")
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT, help="the JSON results")
    parser.add_argument("--fleet", metavar="LINES,DRIVES,BAUD", help="simulated serial lines")
    args = parser.parse_args()
    fleet = None
    if args.fleet:
        lines, drives, baudrate = (int(v) for v in args.fleet.split(","))
        fleet = (lines, drives, baudrate)
    if not Path("/proc/self/stat").exists():
        raise SystemExit("this benchmark reads /proc: Linux only")

    load_before = os.getloadavg()
    figures = measure(args.duration, args.interval, fleet)
    load_after = os.getloadavg()
    results = {
        **results_file.provenance("daemon_footprint"),
        "load_average_before": load_before,
        "load_average_after": load_after,
        "uptime": _uptime(),
        "fleet": (
            "the demo (fcmaster/demo.yaml): 2 simulated lines in-process, 10 drives, HTTP"
            if fleet is None
            else f"{fleet[0]} FC lines x {fleet[1]} drives at {fleet[2]} baud on ptys, "
            "simulated in a process each; monitor-only, default monitor list, HTTP"
        ),
        **figures,
    }
    results_file.write(args.output, results)

    r, c = figures["rss_mib"], figures["cpu"]
    print(
        f"fcmaster run ({results['fleet']}) over {figures['window_s']:.0f} s, "
        f"after {figures['startup_s']:.1f} s "
        f"to show its drives:\n"
        f"  RSS {r['start']:.1f} MiB at start, peak {r['peak']:.1f}, final {r['final']:.1f}; "
        f"last half {r['growth_last_half']:+.2f} MiB "
        f"(slope {r['slope_last_half_per_min']:+.3f} MiB/min)\n"
        f"  CPU {c['mean_pct_of_one_core']:.1f} % of one core ({c['seconds']:.1f} s; "
        f"{c['s_per_1000_transactions']:.3f} s per 1000 transactions)\n"
        f"  {figures['transactions_per_s']:.0f} transactions/s ("
        + ", ".join(f"{n} {v['transactions_per_s']:.0f}" for n, v in figures["lines"].items())
        + f"); SIGTERM: exit {figures['exit_code']} after {figures['stop_s']:.2f} s\n"
        f"  load average {load_before[0]:.2f} before, {load_after[0]:.2f} after "
        f"({os.cpu_count()} CPUs); results in {args.output}"
    )
    return 0 if figures["exit_code"] == 0 else 1


def _uptime() -> str:
    try:
        return subprocess.run(
            ["uptime"], capture_output=True, text=True, check=True, timeout=10
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


if __name__ == "__main__":
    raise SystemExit(main())
