"""The running config in Prometheus metrics: which one runs, and how reloads went."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fcmaster.adapters.metrics import Exposition, labels


def render(status: Mapping[str, Any]) -> str:
    """``fcmaster_config_info{hash}`` and ``fcmaster_config_reloads_total{outcome}``."""
    x = Exposition()
    x.add(
        "fcmaster_config_info",
        "gauge",
        "The running config (1), by the hash that GET /api/v1/status shows.",
        1,
        labels({"hash": status["hash"]}),
    )
    for outcome in ("applied", "refused"):
        x.add(
            "fcmaster_config_reloads_total",
            "counter",
            "Config reloads (SIGHUP) by outcome.",
            status.get("reloads", {}).get(outcome, 0),
            labels({"outcome": outcome}),
        )
    return x.render()
