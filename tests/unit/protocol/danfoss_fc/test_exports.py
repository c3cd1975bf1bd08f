"""Every name in ``fcmaster.protocol.danfoss_fc.__all__`` exists (STYLE.md §8)."""

from __future__ import annotations

import fcmaster.protocol.danfoss_fc as danfoss_fc


def test_all_names_are_exported() -> None:
    missing = [name for name in danfoss_fc.__all__ if not hasattr(danfoss_fc, name)]
    assert missing == []
    assert sorted(danfoss_fc.__all__) == sorted(set(danfoss_fc.__all__))
