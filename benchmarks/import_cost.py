"""What starting fcmaster costs before it does anything: imports and short CLI commands.

Run: ``python benchmarks/import_cost.py [--runs N] [--output PATH]`` (default 15 runs of
each case, about 20 s in all).

Each case runs in a fresh interpreter (the same Python as this script), one at a time:

- *imports*: ``python -X importtime -c "import MODULE"``, the cumulative microseconds of
  ``MODULE`` as the interpreter reports them (its own start-up and ``site`` excluded);
- *commands*: the wall-clock time of ``python -m fcmaster ARGS`` from start to exit, for
  commands that touch no port (``--help``, ``decode``, ``check`` of the demo config).

Figures are the median and the minimum over the runs; the minimum is the least disturbed
by other work on the machine, and the load is recorded with them.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import results_file

ROOT = Path(__file__).resolve().parent.parent
IMPORTS = (
    "fcmaster.bus.plan",
    "fcmaster.bus",
    "fcmaster.protocol.registry",
    "fcmaster.config",
    "fcmaster.cli",
)
COMMANDS = {
    "help": ("--help",),
    "decode": ("decode", "020e01047f000000000000047f00000d"),
    "check_demo": ("check", "--config", str(ROOT / "config" / "demo.yaml")),
}


def import_us(module: str) -> int:
    """Cumulative import time of ``module`` in a fresh interpreter, in microseconds."""
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-c", f"import {module}"],
        capture_output=True, text=True, check=True, cwd=ROOT,
    )  # fmt: skip
    for line in reversed(done.stderr.splitlines()):
        fields = [field.strip() for field in line.removeprefix("import time:").split("|")]
        if len(fields) == 3 and fields[2] == module:
            return int(fields[1])
    raise RuntimeError(f"no import time reported for {module}")


def command_s(args: tuple[str, ...]) -> float:
    """Wall-clock seconds of ``python -m fcmaster ARGS``, start to exit."""
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "fcmaster", *args],
        capture_output=True, check=True, cwd=ROOT,
    )  # fmt: skip
    return time.perf_counter() - start


def summary(samples: list[float]) -> dict[str, float]:
    """Median and minimum of ``samples``."""
    return {"median": statistics.median(samples), "min": min(samples)}


def main() -> None:
    """Measure every case and print (and optionally write) the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=15)
    parser.add_argument("--output", type=Path)
    options = parser.parse_args()
    results: dict[str, Any] = results_file.provenance("import_cost")
    results["loadavg_before"] = os.getloadavg()
    results["imports_ms"] = {}
    for module in IMPORTS:
        samples = [import_us(module) / 1000 for _ in range(options.runs)]
        results["imports_ms"][module] = figures = summary(samples)
        print(f"import {module:<28} median {figures['median']:6.1f} ms  min {figures['min']:6.1f}")
    results["commands_ms"] = {}
    for name, args in COMMANDS.items():
        samples = [command_s(args) * 1000 for _ in range(options.runs)]
        results["commands_ms"][name] = figures = summary(samples)
        line = f"fcmaster {' '.join(args)[:40]}"
        print(f"{line:<50} median {figures['median']:6.1f} ms  min {figures['min']:6.1f}")
    results["loadavg_after"] = os.getloadavg()
    print(f"load average before {results['loadavg_before']}, after {results['loadavg_after']}")
    if options.output is not None:
        results_file.write(options.output, results)


if __name__ == "__main__":
    main()
