"""What the strict config reader costs, and what the files it refuses cost to refuse.

Run: ``python benchmarks/config_read.py [--runs N] [--drives N] [--output PATH]`` (default
5 runs, 10,080 drives: 80 FC lines of 126; about a minute in all).

- *large file*: a config of ``--drives`` drives, read by PyYAML's ``safe_load`` (what the
  reader replaced) and by :func:`fcmaster.config_yaml.read` (keys given twice, depth and
  aliases checked), then wholly validated by :func:`fcmaster.config.parse`; in-process, the
  cases taking turns, the median and minimum of the runs in CPU and in wall seconds.
- *refusals*: ``python -m fcmaster check`` on a 1 KB alias bomb (10 levels of 9: 3.5
  billion strings expanded) and on a 100,000-deep list, each in a fresh interpreter: its
  wall time, its peak RSS (the child's ru_maxrss) and its exit code.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import results_file
import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fcmaster.config import parse  # noqa: E402
from fcmaster.config_yaml import read  # noqa: E402


def large_config(drives: int) -> str:
    """``drives`` FC drives, 126 to a line, each with a name, address, control and limit."""
    rows = ["buses:"]
    for n in range(drives):
        bus, address = divmod(n, 126)
        if address == 0:
            rows += [f"  - name: line{bus}", f"    port: /dev/ttyUSB{bus}", "    drives:"]
        rows.append(
            f"      - {{name: drive-{n}, address: {address + 1}, control: bus, "
            "max_frequency_hz: 50}"
        )
    return "\n".join(rows) + "\n"


def bomb(levels: int = 10, width: int = 9) -> str:
    rows = [f"a0: &a0 [{', '.join(['lol'] * width)}]"]
    rows += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * width)}]" for i in range(1, levels)]
    rows.append(f"buses: [{{name: x, port: /dev/ttyUSB0, drives: *a{levels - 1}}}]")
    return "\n".join(rows) + "\n"


def timed(runs: int, cases: dict[str, Callable[[], object]]) -> dict[str, dict[str, float]]:
    """Each case's CPU and wall seconds (median, minimum), the cases taking turns in each run.

    Taking turns spreads the machine's other work over every case alike; CPU time (this
    process's) is what the reading costs, wall time what a user waits under that load.
    """
    cpu: dict[str, list[float]] = {name: [] for name in cases}
    wall: dict[str, list[float]] = {name: [] for name in cases}
    for _ in range(runs):
        for name, work in cases.items():
            start_cpu, start = time.process_time(), time.perf_counter()
            work()
            cpu[name].append(time.process_time() - start_cpu)
            wall[name].append(time.perf_counter() - start)
    return {
        name: {
            "cpu_median_s": statistics.median(cpu[name]),
            "cpu_min_s": min(cpu[name]),
            "wall_median_s": statistics.median(wall[name]),
            "wall_min_s": min(wall[name]),
        }
        for name in cases
    }


def check_child(text: str) -> dict[str, Any]:
    """``fcmaster check`` on ``text`` in a fresh interpreter: time, peak RSS, exit, message."""
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "plant.yaml"
        config.write_text(text)
        before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        start = time.perf_counter()
        done = subprocess.run(
            [sys.executable, "-m", "fcmaster", "check", "--config", str(config)],
            capture_output=True, text=True, cwd=ROOT, timeout=600, check=False,
        )  # fmt: skip
        wall = time.perf_counter() - start
        peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return {
        "file_bytes": len(text.encode()),
        "wall_s": wall,
        # the children's high-water mark so far: this child's if it is the largest yet
        "peak_rss_mib": max(peak, before) / 1024,
        "exit_code": done.returncode,
        "message": done.stderr.strip().splitlines()[-1:],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--drives", type=int, default=10_080)
    parser.add_argument(
        "--output", type=Path, default=ROOT / "benchmarks" / "results" / "config_read.json"
    )
    args = parser.parse_args()
    text = large_config(args.drives)
    out: dict[str, Any] = results_file.provenance("config_read")
    out["large_file"] = {
        "drives": args.drives,
        "bytes": len(text.encode()),
        **timed(
            args.runs,
            {
                "yaml_safe_load": lambda: yaml.safe_load(text),
                "strict_read": lambda: read(text, []),
                "config_parse": lambda: parse(text, env={}),
            },
        ),
    }
    out["load_average_after"] = os.getloadavg()
    deep = 100_000
    out["refusals"] = {
        "alias_bomb": check_child(bomb()),
        "list_100000_deep": check_child("buses: " + "[" * deep + "]" * deep + "\n"),
    }
    results_file.write(args.output, out)
    print(args.output.read_text())


if __name__ == "__main__":
    main()
