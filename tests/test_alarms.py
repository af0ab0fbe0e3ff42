"""The alarm lifecycle: on-delays in seconds, hysteresis, latch and acknowledge, levels and
escalation, rate of rise, a difference to a reference ROI; rules from the settings."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from thermodepth.alarms import AlarmRule, AlarmTracker, event_line
from thermodepth.errors import InputError
from thermodepth.measure import RoiStats
from thermodepth.pipeline import Settings


def roi(
    name: str, max_c: float, mean_c: float | None = None, min_c: float | None = None
) -> RoiStats:
    mean = max_c if mean_c is None else mean_c
    return RoiStats(name, 100, mean, max_c, mean if min_c is None else min_c, 0.1)


def run(tracker: AlarmTracker, series: list[list[RoiStats]], dt: float = 0.5) -> list[list[str]]:
    """The events of each frame as ``event rule`` strings."""
    return [
        [f"{e['event']} {e['rule']}" for e in tracker.update(i * dt, i, [], rois)]
        for i, rois in enumerate(series)
    ]


def test_for_s_is_an_on_delay_in_seconds_and_hysteresis_holds_it() -> None:
    rule = AlarmRule("panel", above_c=60.0, what="p", for_s=1.0, clear_below_c=55.0)
    t = AlarmTracker([rule])
    values = [61, 61, 61, 58, 61, 61, 61, 58, 57, 54, 54]  # a frame every 0.5 s
    got = run(t, [[roi("p", v)] for v in values])
    assert got[2] == ["alarm panel"]  # 1 s after it began (frames 0, 1, 2)
    assert all(not e for e in got[3:9])  # 58, 57: between the limits, it stays raised
    assert got[9] == ["clear panel"] and got[10] == []
    # a dip below the limit restarts the delay: 61 at 3.5, 58, 61 ... raised only after 1 s
    t2 = AlarmTracker([rule])
    got2 = run(t2, [[roi("p", v)] for v in [61, 61, 58, 61, 61, 61]])
    assert got2 == [[], [], [], [], [], ["alarm panel"]]


def test_clear_for_s_and_latch_until_acknowledged() -> None:
    rule = AlarmRule("bus", above_c=80.0, what="b", clear_for_s=1.0, latch=True)
    t = AlarmTracker([rule])
    got = run(t, [[roi("b", v)] for v in [85, 70, 70, 70, 70]])
    assert got[0] == ["alarm bus"] and all(not e for e in got[1:])  # latched: no clear
    after = t.acknowledge("bus", "operator jane", at_utc="2026-11-26T10:00:00+00:00")
    assert after[0]["by"] == "operator jane" and after[0]["frame"] == 4  # the last frame's
    assert [e["event"] for e in after] == ["acknowledged", "clear"]  # latched, value back
    assert t.update(3.0, 6, [], [roi("b", 70)]) == []
    assert after[1]["acknowledged"] == {
        "by": "operator jane",
        "at_utc": "2026-11-26T10:00:00+00:00",
    }
    assert t.raised == []
    with pytest.raises(ValueError, match="not raised"):
        t.acknowledge("bus", "jane")
    with pytest.raises(KeyError):
        t.acknowledge("nope", "jane")
    # acknowledged while still hot: it clears when the value comes back, no new ack needed
    t.update(4.0, 7, [], [roi("b", 90)])
    assert [e["event"] for e in t.acknowledge("bus", "jane")] == ["acknowledged"]
    assert t.update(4.5, 8, [], [roi("b", 90)]) == []
    assert run(t, [[roi("b", 70)]] * 4, dt=0.5)[-1] == []
    assert t.raised == []


def test_levels_escalate_on_one_subject() -> None:
    warn = AlarmRule("warm", above_c=50.0, what="m", level="warning")
    alarm = AlarmRule("hot", above_c=70.0, what="m", level="alarm")
    other = AlarmRule("other", above_c=70.0, what="n")
    t = AlarmTracker([warn, alarm, other])
    got = run(t, [[roi("m", v), roi("n", v)] for v in [55, 75, 45]])
    assert got[0] == ["alarm warm"]
    assert got[1] == ["escalated hot", "alarm other"]  # the warning on m was raised
    assert got[2] == ["clear warm", "clear hot", "clear other"]


def test_below_rise_and_delta_rules() -> None:
    rules = [
        AlarmRule("cold", below_c=5.0, what="pipe", clear_above_c=8.0),
        AlarmRule("rising", rise_c_per_min=6.0, rise_window_s=10.0, what="pipe", stat="mean"),
        AlarmRule("hotter", delta_c=10.0, relative_to="ref", what="pipe", stat="mean"),
    ]
    t = AlarmTracker(rules)
    ref = roi("ref", 20.0)
    # 3 C in 1.5 s is 120 C/min; 12 C above the reference is a delta above 10
    series = [[roi("pipe", 20.0 + k, 20.0 + k, 4.0), ref] for k in np.arange(0, 30, 1.5)]
    events = [e for i, rois in enumerate(series) for e in t.update(i * 0.5, i, [], rois)]
    kinds = [(e["event"], e["rule"]) for e in events]
    assert ("alarm", "cold") in kinds  # its min, 4 C, is below 5
    assert ("alarm", "rising") in kinds and ("alarm", "hotter") in kinds
    rising = next(e for e in events if e["rule"] == "rising")
    assert rising["value_c"] == pytest.approx(180.0, rel=1e-6)  # 1.5 C per 0.5 s
    hotter = next(e for e in events if e["rule"] == "hotter")
    assert (
        hotter["value_c"] > 10.0 and hotter["condition"] == "more than 10 C above ref for 1 frame"
    )
    assert rising["frame"] >= 10  # the rate waits for half its window of frames


def test_rules_from_the_settings_one_line_each(tmp_path: Path) -> None:
    good = tmp_path / "s.yaml"
    good.write_text(
        "rois: [{name: bus, rect: [0, 0, 10, 10]}, {name: ref, rect: [10, 0, 20, 10], "
        "emissivity: 0.6}]\n"
        "alarms:\n"
        "  - {name: w, what: bus, level: warning, above_c: 50, for_s: 2, clear_below_c: 45}\n"
        "  - {name: d, what: bus, delta_c: 5, relative_to: ref, latch: true}\n"
        "  - {name: legacy, above_c: 60, for_frames: 3}\n"
    )
    s = Settings.load(good)
    assert [a.rule().condition() for a in s.alarms] == [
        "above 50 C for 2 s",
        "more than 5 C above ref for 1 frame",
        "above 60 C for 3 frames",
    ]
    bad = {
        "{name: a, above_c: 50, below_c: 10}": "give exactly one of above_c, below_c",
        "{name: a}": "give exactly one of above_c, below_c, rise_c_per_min, delta_c, "
        "area_cm2_above, priority_at_most (got none)",
        "{name: a, delta_c: 3}": "delta_c and relative_to go together",
        "{name: a, above_c: 50, for_s: 2, for_frames: 3}": "give for_s (seconds) or for_frames",
        "{name: a, above_c: 50, clear_below_c: 55}": "clear_below_c must be at or below 50",
        "{name: a, below_c: 5, clear_below_c: 3}": "clear_below_c is for above_c or delta_c",
        "{name: a, above_c: 50, level: critical}": "level: Input should be 'warning' or 'alarm'",
        "{name: a, what: bus, delta_c: 2, relative_to: nope}": "relative_to='nope' is not an ROI",
        "{name: a, above_c: 50, stat: mean}": "stat is for an ROI",
    }
    for rule, message in bad.items():
        path = tmp_path / "bad.yaml"
        path.write_text(f"rois: [{{name: bus, rect: [0, 0, 10, 10]}}]\nalarms: [{rule}]\n")
        with pytest.raises(InputError) as info:
            Settings.load(path)
        assert message in str(info.value) and "\n" not in str(info.value), rule


def test_an_event_reads_as_one_line() -> None:
    t = AlarmTracker([AlarmRule("hot", above_c=60.0, what="p", for_frames=2, level="warning")])
    t.update(0.0, 0, [], [roi("p", 61.0)])
    (e,) = t.update(0.1, 1, [], [roi("p", 61.5)])
    assert event_line(e) == "ALARM hot [warning]: 61.5 C (above 60 C for 2 frames), frame 1"
