from fcmaster.history import History, Series

FREQUENCY = Series("output_frequency_hz", "Output frequency", "Hz")


def test_a_drive_keeps_two_samples_a_spacing_and_always_the_latest() -> None:
    history = History(window_s=60.0, spacing_s=2.0)
    for n in range(11):  # every 0.5 s for 5 s
        history.record_drive(
            "l/d", 100.0 + n * 0.5, {FREQUENCY.key: float(n)}, {FREQUENCY.key: FREQUENCY}
        )
    out = history.drive("l/d")
    assert out["t"] == [100.0, 101.5, 103.0, 104.5, 105.0]  # no three within 2 s
    (series,) = out["series"]
    assert (series["key"], series["name"], series["unit"]) == (
        "output_frequency_hz",
        "Output frequency",
        "Hz",
    )
    assert series["data"] == [0.0, 3.0, 6.0, 9.0, 10.0]


def test_a_drive_ring_forgets_what_is_older_than_its_window_and_stays_bounded() -> None:
    history = History(window_s=10.0, spacing_s=1.0)
    for n in range(1000):
        history.record_drive("l/d", float(n), {FREQUENCY.key: None}, {FREQUENCY.key: FREQUENCY})
    t = history.drive("l/d")["t"]
    assert t[0] >= 989.0
    assert t[-1] == 999.0
    assert len(t) <= 21


def test_a_series_first_seen_later_has_gaps_before_it() -> None:
    history = History(window_s=60.0, spacing_s=1.0)
    current = Series("16-14", "Motor Current", "A")
    history.record_drive("l/d", 1.0, {FREQUENCY.key: 10.0}, {FREQUENCY.key: FREQUENCY})
    history.record_drive(
        "l/d",
        2.0,
        {FREQUENCY.key: 11.0, "16-14": 4.0},
        {FREQUENCY.key: FREQUENCY, current.key: current},
    )
    series = {s["key"]: s["data"] for s in history.drive("l/d")["series"]}
    assert series == {"output_frequency_hz": [10.0, 11.0], "16-14": [None, 4.0]}


def test_a_line_s_counters_become_rates_between_samples() -> None:
    history = History(window_s=60.0, spacing_s=1.0)
    before = {"requests": 100, "replies": 99, "timeouts": 1, "retries": 0,
              "checksum_errors": 0, "malformed": 0, "unexpected": 0}  # fmt: skip
    after = {"requests": 850, "replies": 840, "timeouts": 11, "retries": 5,
             "checksum_errors": 2, "malformed": 1, "unexpected": 2, "utilisation": 0.9}  # fmt: skip
    history.record_line("l", 10.0, before)
    history.record_line("l", 15.0, after)
    out = history.line("l")
    assert out["t"] == [15.0]
    series = out["series"]
    assert (series["requests_per_s"], series["timeouts_per_s"], series["errors_per_s"]) == (
        [150.0],
        [2.0],
        [1.0],
    )
    assert series["utilisation"] == [0.9]
    assert history.line("other")["t"] == []
