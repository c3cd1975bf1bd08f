"""Idle polls are encoded once per drive and monitor slot, and stay what they were."""

import pytest

from fcmaster.errors import UsageError
from fcmaster.protocol.codec import DriveCodec, Exchange
from fcmaster.protocol.danfoss_fc.codec import FcCodec
from fcmaster.protocol.drive import ControlIntent, Motion
from fcmaster.protocol.enc.codec import EncCodec
from fcmaster.protocol.mitsubishi.codec import MitsubishiCodec
from fcmaster.protocol.polls import PollCache


@pytest.mark.parametrize(
    ("codec", "monitored"),
    [(FcCodec(), "16-13"), (MitsubishiCodec(), "H6F"), (EncCodec(), "11/0003")],
)
def test_a_repeated_poll_is_the_same_exchange_with_the_bytes_a_fresh_read_builds(
    codec: DriveCodec, monitored: str
) -> None:
    key = codec.parameter(monitored)
    first = codec.poll(5, None, key)
    assert codec.poll(5, None, key) is first
    assert first.request == codec.read(5, key, 0, None)[0].request
    assert codec.poll(6, None, key).request != first.request
    assert codec.poll(5, None, None) is codec.poll(5, None, None)


def test_an_fc_poll_follows_a_changed_intent() -> None:
    codec = FcCodec()
    run = ControlIntent(motion=Motion.RUN, reference_pct=40.0)
    stop = ControlIntent()
    assert codec.poll(3, run, None).request == codec.control(3, run)[0].request
    assert codec.poll(3, stop, None).request == codec.control(3, stop)[0].request
    assert codec.poll(3, run, None).request != codec.poll(3, stop, None).request
    assert codec.poll(3, ControlIntent(motion=Motion.RUN, reference_pct=40.0), None) is (
        codec.poll(3, run, None)
    )


def test_a_refused_poll_raises_every_time_and_is_not_kept() -> None:
    calls = []

    def build(address: int, intent: object, read: object) -> object:
        calls.append(address)
        raise UsageError("no such drive")

    cache = PollCache(build)  # type: ignore[arg-type]
    for _ in range(2):
        with pytest.raises(UsageError):
            cache.get(1, None, None)
    assert calls == [1, 1]


def test_the_cache_starts_over_past_its_limit(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(PollCache, "LIMIT", 4)
    codec = FcCodec()
    built: list[int] = []

    def build(address: int, intent: ControlIntent | None, read: object) -> Exchange:
        built.append(address)
        return codec.control(address, intent)[0]

    cache = PollCache(build)
    for address in range(1, 7):
        cache.get(address, None, None)
    cache.get(6, None, None)  # kept since the restart
    cache.get(1, None, None)  # forgotten: built again
    assert built == [1, 2, 3, 4, 5, 6, 1]
