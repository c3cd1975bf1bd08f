"""Where a store of records lives and how big and old it may grow (config and stores share it).

Kept apart from :mod:`fcmaster.store` so that reading a config loads no SQLite and no
logging.
"""

from __future__ import annotations

from dataclasses import dataclass

MEMORY = ":memory:"


@dataclass(slots=True, frozen=True, kw_only=True)
class StoreSettings:
    """A store's file (None: in memory) and its bounds (the config's ``journal:``)."""

    path: str | None = None
    max_mb: float = 100.0
    max_days: float = 90.0

    @property
    def max_bytes(self) -> int:
        """``max_mb`` in bytes."""
        return int(self.max_mb * 1024 * 1024)

    @property
    def max_age_s(self) -> float:
        """``max_days`` in seconds."""
        return self.max_days * 86400.0
