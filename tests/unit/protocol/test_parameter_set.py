"""Parameter sets: what each protocol's set holds, how sets compare, what a file may say."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fcmaster.bus.codecs import codec_for
from fcmaster.bus.plan import LinePlan
from fcmaster.errors import UsageError
from fcmaster.protocol.codec import DriveError, ParameterKey, ParameterValue
from fcmaster.protocol.parameter_set import (
    Entry,
    ParameterSet,
    compare,
    identity_mismatches,
    judge,
    profile_for,
    read_set,
)


def fc_set(**raws: int) -> ParameterSet:
    out = ParameterSet(protocol="danfoss-fc", address=1)
    out.identity["15-40"] = Entry(name="FC Type", value="FC-302")
    for key, raw in raws.items():
        out.parameters[key.replace("_", "-").lstrip("p")] = Entry(
            name=key, value=raw / 100, unit="s", raw=raw
        )
    return out


def test_each_protocols_set_is_its_writable_settings_and_names_the_codecs_way() -> None:
    fc = profile_for("danfoss-fc")
    members = [key for key, _ in fc.members]
    assert "3-41" in members
    assert "16-13" not in members  # a reading
    assert "15-40" not in members  # identity, read-only text
    assert [key for key, _ in fc.identity][:1] == ["15-40"]
    assert "8-31" in fc.link_settings
    assert fc.changeable_while_running <= set(members)
    mitsubishi = profile_for("mitsubishi")
    assert ("Pr.7", "acceleration time") in mitsubishi.members
    assert mitsubishi.changeable_while_running == frozenset()
    enc = profile_for("enc")
    assert ("F0.08", "Acceleration time 1") in enc.members
    assert {"F2.14", "F2.15"} <= enc.link_settings
    with pytest.raises(UsageError):
        profile_for("modbus")


def test_compare_goes_by_raw_and_reports_refusals_and_absences() -> None:
    left = fc_set(p3_41=300, p3_42=300)
    right = fc_set(p3_41=300, p3_42=450)
    right.parameters["3-41"] = Entry(name="x", value=3.0000001, unit="s", raw=300)
    right.parameters["8-36"] = Entry(name="late", refused=DriveError(0, "no such parameter"))
    differences = compare(left, right)
    assert [(d.parameter, d.left is None, d.right is None) for d in differences] == [
        ("3-42", False, False),
        ("8-36", True, False),
    ]
    assert differences[1].right is not None
    assert differences[1].right.shown() == "refused (error 0: no such parameter)"
    assert compare(left, left) == []
    with pytest.raises(UsageError, match="cannot compare"):
        compare(left, ParameterSet(protocol="enc", address=1))


def test_a_set_survives_its_file_form_and_a_bad_one_names_every_problem() -> None:
    original = fc_set(p3_41=300)
    original.parameters["8-36"] = Entry(name="late", refused=DriveError(0, "gone"))
    again = ParameterSet.from_dict(original.to_dict())
    assert again == original
    with pytest.raises(UsageError) as caught:
        ParameterSet.from_dict(
            {"format": "other", "protocol": "profibus", "parameters": {"3-41": {"value": True}}}
        )
    message = str(caught.value)
    for part in ("format", "protocol", "address", "3-41.value"):
        assert part in message
    with pytest.raises(UsageError):
        ParameterSet.from_dict(["not", "a", "mapping"])


def test_identity_must_match_on_the_type_not_the_serial_number() -> None:
    profile = profile_for("danfoss-fc")
    saved, drive = fc_set(), fc_set()
    saved.identity["15-51"] = Entry(name="serial", value="A1")
    drive.identity["15-51"] = Entry(name="serial", value="B2")
    assert identity_mismatches(profile, saved, drive) == []
    drive.identity["15-40"] = Entry(name="FC Type", value="FC-301")
    assert identity_mismatches(profile, saved, drive) == [
        "15-40 (FC Type): the file says FC-302, the drive FC-301"
    ]


async def test_read_set_reads_identity_then_members_and_keeps_refusals() -> None:
    profile = profile_for("enc")
    asked: list[str] = []

    async def read(name: str) -> ParameterValue | DriveError:
        asked.append(name)
        if name == "F2.17":
            return DriveError(30, "refused")
        return ParameterValue(parameter=ParameterKey(name, 0), index=0, raw=7, value=7.0, unit="")

    progress: list[tuple[int, int]] = []
    found = await read_set(profile, 5, read, on_progress=lambda d, t, _: progress.append((d, t)))
    assert asked == ["15/0000", *(key for key, _ in profile.members)]
    assert found.parameters["F2.17"].refused == DriveError(30, "refused")
    assert found.parameters["F0.08"].raw == 7
    assert progress[-1] == (len(asked), len(asked))


def _fc_encode(key: str, value: float) -> object:
    codec = codec_for(LinePlan(name="t", port="", protocol="danfoss-fc"))
    return codec.write(1, codec.parameter(key), 0, value, None, persist=True)


def test_the_sets_hold_no_factory_reset_and_operation_modes_are_line_settings() -> None:
    fc = profile_for("danfoss-fc")
    assert "14-22" not in dict(fc.members)  # Operation Mode: "initialise" resets the drive
    assert "1-20" not in dict(fc.members)  # motor data: not in this set
    assert fc.frequency_ceilings == {"4-14"} <= set(dict(fc.members))
    mitsubishi = profile_for("mitsubishi")
    assert "Pr.79" in mitsubishi.link_settings  # operation mode: never restored
    assert mitsubishi.frequency_ceilings == {"Pr.1", "Pr.18"}
    ranged = {key for key, _, _ in fc.ranges}
    assert ranged == {"3-41", "3-42", "3-51", "3-52", "3-81", "8-03"} <= set(dict(fc.members))


def test_judge_refuses_what_is_outside_the_set_or_cannot_be_sent_and_bounds_ceilings() -> None:
    fc = profile_for("danfoss-fc")
    saved = fc_set()
    saved.parameters["14-22"] = Entry(name="Operation Mode", value=2.0, raw=2)
    saved.parameters["8-03"] = Entry(name="", value=-5.0, unit="s")
    saved.parameters["4-14"] = Entry(value=500.0, unit="Hz")
    saved.parameters["8-31"] = Entry(value=-1.0)  # a line setting: never written, not judged
    saved.parameters["3-41"] = Entry(value="fast")
    saved.parameters["3-42"] = Entry(value=0.0, unit="s")  # sendable, but below 0.01 s
    saved.parameters["3-81"] = Entry(value=0.01, unit="s")  # the guide's least: fine
    verdict = judge(fc, saved, _fc_encode, max_frequency_hz=50.0)
    assert verdict.refused == (
        "14-22 (Operation Mode): not in the danfoss-fc parameter set, and a restore writes only "
        "the set's own parameters",
        "8-03 (Control Word Timeout Time) = -5 s: cannot be written (8-03: raw value -50 is "
        "outside 0…4294967295)",
        "3-41 (Ramp 1 Ramp Up Time): 'fast' is not a number",
        "3-42 (Ramp 1 Ramp Down Time) = 0 s: outside 0.01-3600 s",
    )
    assert verdict.beyond_limits == (
        "4-14 (Motor Speed High Limit [Hz]) = 500 Hz is above the drive's configured "
        "max_frequency_hz 50",
    )
    assert judge(fc, saved, _fc_encode).beyond_limits == ()  # no configured limit known


@given(st.floats(allow_nan=True, allow_infinity=True))
def test_judge_refuses_exactly_the_values_the_codec_cannot_send(value: float) -> None:
    fc = profile_for("danfoss-fc")
    saved = ParameterSet(protocol="danfoss-fc", address=1)
    saved.parameters["4-12"] = Entry(value=value, unit="Hz")  # no range of its own
    try:
        _fc_encode("4-12", value)
    except UsageError:
        sendable = False
    else:
        sendable = True
    assert bool(judge(fc, saved, _fc_encode).refused) is not sendable
