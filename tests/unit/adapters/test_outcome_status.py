"""Every outcome has its HTTP status, as DESIGN.md "Commands" lists them."""

from __future__ import annotations

from fcmaster.adapters.api import OUTCOME_STATUS
from fcmaster.bus.commands import Outcome


def test_every_outcome_maps_to_the_status_design_names() -> None:
    design = {
        "done": 200,
        "refused": 409,
        "superseded": 409,
        "not_allowed": 403,
        "invalid": 422,
        "timeout": 504,
        "unconfirmed": 504,
        "cancelled": 503,
    }
    assert {outcome.value: status for outcome, status in OUTCOME_STATUS.items()} == design
    assert set(OUTCOME_STATUS) == set(Outcome)
