"""What the Sparkplug B edge node costs a line: its rate and wake-up lateness without and with it.

Run: ``python benchmarks/sparkplug_load.py [--drives 32] [--baudrate 19200] [--window 15]
[--cycles 3] [--output FILE]`` (a few minutes; needs mosquitto).

The plant is ``opcua_load.py``'s: ``fcmaster sim`` serves one simulated FC line of
``--drives`` drives on a pseudo-terminal, every drive sent towards 50 Hz on a 10-minute
ramp, so every poll reads a new output frequency, current and power; ``fcmaster run``
polls it through the real serial path under ``lateness_tap.py``, with the HTTP API. Beside
it: a mosquitto on loopback, and a Sparkplug host application in a process of its own,
subscribed to ``spBv1.0/#`` and decoding every payload. The broker and the host run on
other machines in a plant; here they share the gateway's two cores, so they run at the
lowest priority (``nice 19``) to take only what the gateway leaves.

Windows of ``--window`` seconds alternate, ``--cycles`` times: **without** the edge node,
and **with** it (a ``sparkplug:`` section with a store on disk, added and removed by a
reload — SIGHUP — which starts or stops the adapter alone and leaves the line polling; a
window starts ``--settle-s`` after the node connected). With it, every change of every
drive is a DDATA (and a row in the store). Per window: the line's transactions per
second and the mean gap between good replies of its drive answered least often
(``/api/v1/buses``), its timers' wake-up lateness (p50 and p99 of the raw samples, and the
histogram's p99 bucket), the CPU of the daemon, the broker and the host (share of one
core), and the Sparkplug messages and metrics the host decoded per second. The summary
pools the windows of each kind: the rate with ÷ without (the target: ≥ 0.97, as for OPC
UA), lateness p50/p99 without and with. Linux only (``/proc``).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Final

import aiomqtt
import lateness_tap
import results_file
from daemon_footprint import _cpu_s, _free_port
from opcua_load import _buses, _http, _lines, _ramp_all, line_figures, plant
from sparkplug_outage import MOSQUITTO, mosquitto_config

from fcmaster.adapters.sparkplug.payload import decode_payload

DEFAULT_OUTPUT: Final = Path(__file__).resolve().parent / "results" / "sparkplug_load.json"
RELOAD_S: Final = 60.0  # a reload must have started or stopped the edge node within this
NICE: Final = ["nice", "-n", "19"]


def _config(drives: int, baud: int, http: int, folder: Path, broker: int | None) -> str:
    """The daemon's config: the line, HTTP, and the edge node when ``broker`` is given."""
    text = _buses(1, drives, folder, baud) + _http(http)
    text += "logging: {level: info, format: json}\n"
    if broker is not None:
        text += (
            f"sparkplug:\n  url: mqtt://127.0.0.1:{broker}\n  group_id: Plant\n"
            f"  edge_node_id: bench\n  store: {folder / 'spool' / 'sparkplug.db'}\n"
        )
    return text


async def serve_host(port: int, counts: Path) -> None:
    """``--serve-host``: decode every Sparkplug message; the counts in ``counts`` twice a second."""
    seen = {"messages": 0, "metrics": 0}

    async def keep() -> None:
        while True:
            await asyncio.sleep(0.5)
            text = json.dumps(seen)
            await asyncio.to_thread(counts.write_text, text)

    keeper = asyncio.create_task(keep())
    while not keeper.done():
        try:
            async with aiomqtt.Client("127.0.0.1", port) as client:
                await client.subscribe("spBv1.0/#")
                async for message in client.messages:
                    seen["messages"] += 1
                    if "/STATE/" not in message.topic.value:
                        assert isinstance(message.payload, bytes | bytearray)
                        seen["metrics"] += len(decode_payload(bytes(message.payload)).metrics)
        except aiomqtt.MqttError:
            await asyncio.sleep(0.1)


def _counts(path: Path) -> dict[str, int]:
    try:
        found: dict[str, int] = json.loads(path.read_text())
    except (OSError, ValueError):
        return {"messages": 0, "metrics": 0}
    return found


def _reload(
    daemon: subprocess.Popen[bytes], config: Path, text: str, event: str, pause: threading.Event
) -> None:
    """Write ``text`` to ``config``, reload, and wait until the log tells ``event`` once more."""
    log = config.parent / "run.log"
    before = log.read_text().count(event)
    config.write_text(text)
    daemon.send_signal(signal.SIGHUP)
    deadline = time.monotonic() + RELOAD_S
    while log.read_text().count(event) <= before:
        if time.monotonic() > deadline:
            raise SystemExit(f"no {event} within {RELOAD_S} s of the reload")
        pause.wait(0.1)


def _window(
    base: str, seconds: float, pids: dict[str, int], counts: Path, pause: threading.Event
) -> dict[str, Any]:
    before, t0 = _lines(base), time.monotonic()
    cpu0, seen0 = {k: _cpu_s(p) for k, p in pids.items()}, _counts(counts)
    pause.wait(seconds)
    after, took = _lines(base), time.monotonic() - t0
    cpu1, seen1 = {k: _cpu_s(p) for k, p in pids.items()}, _counts(counts)
    return {
        "seconds": took,
        "span": (t0, t0 + took),
        "lines": line_figures(before, after, took),
        "cpu": {k: (cpu1[k] - cpu0[k]) / took for k in pids},
        "host_messages_per_s": (seen1["messages"] - seen0["messages"]) / took,
        "host_metrics_per_s": (seen1["metrics"] - seen0["metrics"]) / took,
    }


def _measure(args: argparse.Namespace, folder: Path) -> tuple[list[dict[str, Any]], Any]:
    http = _free_port()
    broker_port, broker_config = mosquitto_config(folder)
    config = folder / "plant.yaml"
    without = _config(args.drives, args.baudrate, http, folder, None)
    with_node = _config(args.drives, args.baudrate, http, folder, broker_port)
    config.write_text(without)
    counts = folder / "host.json"
    broker = subprocess.Popen([*NICE, MOSQUITTO, "-c", str(broker_config)],
                              stderr=subprocess.DEVNULL)  # fmt: skip
    host = subprocess.Popen([*NICE, sys.executable, __file__, "--serve-host", str(broker_port),
                             str(counts)])  # fmt: skip
    pause = threading.Event()
    base = f"http://127.0.0.1:{http}"
    windows: list[dict[str, Any]] = []
    try:
        with plant(config, 1, base, pause) as daemon:
            pids = {"daemon": daemon.pid, "broker": broker.pid, "host": host.pid}
            _ramp_all(base)
            pause.wait(args.settle_s)
            for cycle in range(args.cycles):
                found = _window(base, args.window, pids, counts, pause)
                windows.append({"cycle": cycle, "sparkplug": False, **found})
                _reload(daemon, config, with_node, '"sparkplug.connected"', pause)
                pause.wait(args.settle_s)
                found = _window(base, args.window, pids, counts, pause)
                windows.append({"cycle": cycle, "sparkplug": True, **found})
                _reload(daemon, config, without, '"sparkplug.stopped"', pause)
                pause.wait(args.settle_s)
                print(json.dumps(windows[-2:], default=str)[:800], flush=True)
    finally:
        for process in (host, broker):
            process.terminate()
            process.wait(timeout=30)
    return windows, lateness_tap.load(folder / "lateness.json")


def _pooled(raw: dict[str, list[tuple[float, float]]], windows: list[dict[str, Any]]) -> Any:
    """The line's lateness samples of all ``windows`` together: p50 and p99 (seconds)."""
    values = [
        s for w in windows for line in raw.values() for s in lateness_tap.taken(line, *w["span"])
    ]
    return {
        "p50_s": lateness_tap.quantile(values, 0.5),
        "p99_s": lateness_tap.quantile(values, 0.99),
        "samples": len(values),
    }


def _mean(values: list[float]) -> float | None:
    return sum(values) / len(values) if values else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drives", type=int, default=32)
    parser.add_argument("--baudrate", type=int, default=19200)
    parser.add_argument("--window", type=float, default=15.0)
    parser.add_argument("--cycles", type=int, default=3)
    parser.add_argument("--settle-s", type=float, default=3.0)
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    parser.add_argument("--serve-host", nargs=2, metavar=("PORT", "FILE"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.serve_host is not None:
        port, counts = args.serve_host
        asyncio.run(serve_host(int(port), Path(counts)))
        return
    with tempfile.TemporaryDirectory() as temp:
        windows, raw = _measure(args, Path(temp))
    for window in windows:
        start, end = window["span"]
        window["lateness_p50_raw_s"] = [
            lateness_tap.quantile(lateness_tap.taken(s, start, end), 0.5) for s in raw.values()
        ]
        window["lateness_p99_raw_s"] = [lateness_tap.p99(s, start, end) for s in raw.values()]
        window["lateness_samples"] = [sum(start <= t < end for t, _ in s) for s in raw.values()]
    kinds = {
        "without": [w for w in windows if not w["sparkplug"]],
        "with": [w for w in windows if w["sparkplug"]],
    }
    summary: dict[str, Any] = {}
    for kind, ws in kinds.items():
        summary[f"rate_{kind}_per_s"] = _mean([w["lines"]["line1"]["rate_per_s"] for w in ws])
        summary[f"slowest_drive_gap_{kind}_s"] = max(
            w["lines"]["line1"]["slowest_drive_gap_s"] or 0.0 for w in ws
        )
        summary[f"lateness_{kind}"] = _pooled(raw, ws)
        for process in ("daemon", "broker", "host"):
            summary[f"cpu_{process}_{kind}"] = _mean([w["cpu"][process] for w in ws])
        summary[f"host_metrics_{kind}_per_s"] = _mean([w["host_metrics_per_s"] for w in ws])
        summary[f"host_messages_{kind}_per_s"] = _mean([w["host_messages_per_s"] for w in ws])
    rate_without, rate_with = summary["rate_without_per_s"], summary["rate_with_per_s"]
    summary["rate_with_vs_without"] = rate_with / rate_without if rate_without else None
    for window in windows:
        window.pop("span")
    results_file.write(
        args.output,
        {
            **results_file.provenance("sparkplug_load"),
            "drives": args.drives,
            "baudrate": args.baudrate,
            "window_s": args.window,
            "summary": summary,
            "windows": windows,
        },
    )
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
