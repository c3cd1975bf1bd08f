"""The Modbus server's answer budget: a burst at once, then one answer per interval, in turn."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.adapters.modbus import AnswerBudget


def test_a_burst_is_answered_at_once_and_the_rest_in_turn() -> None:
    budget = AnswerBudget(per_s=100.0, burst=10)
    delays = [budget.delay(now=5.0) for _ in range(15)]
    assert delays[:10] == [0.0] * 10
    assert delays[10:] == pytest.approx([0.01, 0.02, 0.03, 0.04, 0.05])
    assert budget.waited == 5


def test_a_quiet_spell_refills_the_burst_and_no_more() -> None:
    budget = AnswerBudget(per_s=100.0, burst=10)
    for _ in range(15):
        budget.delay(now=0.0)
    assert [budget.delay(now=60.0) for _ in range(11)][-2:] == pytest.approx([0.0, 0.01])


@given(st.lists(st.floats(min_value=0.0, max_value=0.5), min_size=1, max_size=300))
def test_answers_never_go_faster_than_the_budget(gaps: list[float]) -> None:
    budget = AnswerBudget(per_s=200.0, burst=20)
    now, answered = 0.0, []
    for gap in gaps:
        now += gap
        answered.append(now + budget.delay(now))
    answered.sort()
    for i in range(len(answered)):  # any stretch holds at most burst + its length × rate
        for j in range(i, len(answered)):
            span = answered[j] - answered[i]
            assert j - i + 1 <= 20 + span * 200.0 + 1e-6
