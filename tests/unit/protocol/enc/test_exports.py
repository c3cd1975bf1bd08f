"""Every name in ``fcmaster.protocol.enc.__all__`` exists (STYLE.md §8)."""

from __future__ import annotations

import fcmaster.protocol.enc as enc


def test_all_names_are_exported() -> None:
    missing = [name for name in enc.__all__ if not hasattr(enc, name)]
    assert missing == []
    assert sorted(enc.__all__) == sorted(set(enc.__all__))
