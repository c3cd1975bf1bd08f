"""Every name in ``fcmaster.protocol.mitsubishi.__all__`` exists (STYLE.md §8)."""

from __future__ import annotations

import fcmaster.protocol.mitsubishi as mitsubishi


def test_all_names_are_exported() -> None:
    missing = [name for name in mitsubishi.__all__ if not hasattr(mitsubishi, name)]
    assert missing == []
    assert sorted(mitsubishi.__all__) == sorted(set(mitsubishi.__all__))
