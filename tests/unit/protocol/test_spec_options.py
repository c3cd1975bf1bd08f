"""A protocol's options carried as (key, value) pairs: checked, defaulted and probed by its spec.

Commissioning's LineOptions, the simulated line's LineSettings and the doctor's LineFormat
hold no field per vendor key; these tests hold the spec's side of that bargain.
"""

from __future__ import annotations

import dataclasses

import pytest

from fcmaster.bus.plan import LinePlan, with_protocol_options
from fcmaster.errors import UsageError
from fcmaster.protocol.registry import PROTOCOLS, spec_for
from fcmaster.protocol.spec import KeyValue, LineKey
from fcmaster.sim.build import simulated_keys
from fcmaster.sim.settings import LineSettings

FORMAT = LineKey(name="address_format", default=126, choices=(31, 126), help="")
WAIT = LineKey(name="wait_time_ms", default=0, minimum=0, maximum=150, step=10, nullable=True,
               help="")  # fmt: skip


@pytest.mark.parametrize(
    ("key", "value", "problem"),
    [
        (FORMAT, 31, ""),
        (FORMAT, 32, "32 is not 31 or 126"),
        (FORMAT, "31", "'31' is not 31 or 126"),  # a choice keeps its type
        (FORMAT, None, "must be given (null is not allowed)"),
        (WAIT, 150, ""),
        (WAIT, None, ""),
        (WAIT, 15, "15 is not 0-150 in steps of 10"),
        (WAIT, 160, "160 is not 0-150 in steps of 10"),
        (WAIT, True, "True is not 0-150 in steps of 10"),
    ],
)
def test_a_line_key_says_why_a_value_cannot_be_its(
    key: LineKey, value: KeyValue, problem: str
) -> None:
    assert key.problem(value) == problem


def test_every_problem_with_a_protocols_options_is_named_at_once() -> None:
    enc = spec_for("enc")
    pairs = (("fault_encoding", "bcd"), ("terminator", "cr"), ("address_encoding", "decimal"))
    assert enc.option_problems(pairs) == [
        "fault_encoding 'bcd' is not hex or decimal",
        "enc lines have no terminator",
    ]


def test_a_simulated_line_takes_only_the_keys_its_drives_take() -> None:
    with pytest.raises(UsageError, match="mitsubishi simulated lines have no terminator"):
        LineSettings(protocol="mitsubishi", protocol_options=(("terminator", "crlf"),))
    with pytest.raises(UsageError, match="response_encoding 'octal' is not hex or decimal"):
        LineSettings(protocol="enc", protocol_options=(("response_encoding", "octal"),))


def test_the_simulated_keys_of_a_plan_are_its_protocols_marked_ones_with_their_values() -> None:
    plan = LinePlan(name="a", port="p", protocol="enc", fault_encoding="decimal")
    assert simulated_keys("enc", plan) == (
        ("address_encoding", "hex"),
        ("response_encoding", "hex"),
        ("fault_encoding", "decimal"),
    )
    # FC's address format is read by no simulated drive: FC drives answer either format.
    assert simulated_keys("danfoss-fc", plan) == ()


def test_a_plan_takes_options_as_fields_where_it_has_them_and_as_pairs_elsewhere() -> None:
    plan = with_protocol_options(
        LinePlan(name="a", port="p"), (("address_format", 31), ("unit_offset", 7))
    )
    assert plan.address_format == 31
    assert plan.protocol_options == (("unit_offset", 7),)
    assert spec_for("danfoss-fc").options_of(plan).address_format == 31


def test_the_doctor_probes_only_the_keys_a_spec_falls_back_on() -> None:
    fc = spec_for("danfoss-fc")
    assert fc.fallback_options == ((("address_format", 31),),)
    plan = LinePlan(name="a", port="p", address_format=31)
    assert fc.probed_options(plan) == (("address_format", 31),)
    assert fc.probed_options() == (("address_format", 126),)
    for name in ("mitsubishi", "enc"):
        assert PROTOCOLS[name].probed_options(plan) == ()


def test_every_fallback_option_set_is_valid_for_its_protocol() -> None:
    for spec in PROTOCOLS.values():
        for pairs in spec.fallback_options:
            assert spec.option_problems(pairs) == [], spec.name
            assert dataclasses.replace(spec.options_of(), **dict(pairs)) != spec.options_of()
