"""Pairing in time: nearest depth frame, threshold, statistics, online == offline."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from thermodepth.frames import DepthFrame, Telemetry, ThermalFrame
from thermodepth.sources.pairing import StreamPairer, nearest_index, pair_times

TELEM = Telemetry(frame_counter=0, fpa_temp_k=308.15, housing_temp_k=307.15)
EMPTY_D = np.zeros((1, 1), np.uint16)


def test_nearest_index_ties_go_to_the_earlier() -> None:
    d = np.array([0.0, 1.0, 2.0])
    assert nearest_index(d, 0.5) == 0
    assert nearest_index(d, 0.51) == 1
    assert nearest_index(d, -5.0) == 0
    assert nearest_index(d, 9.0) == 2
    assert nearest_index(np.array([]), 1.0) == -1


def test_pairs_at_the_rigs_rates() -> None:
    depth = np.arange(300) / 30.0 + 0.004  # 10 s at 30 fps
    thermal = np.arange(87) / 8.7  # 10 s at 8.7 fps
    pairs, stats = pair_times(depth, thermal)
    assert stats.pairs == 87 and stats.dropped == 0
    assert stats.thermal_frames == 87 and stats.depth_frames == 300
    for j, i in pairs:
        assert abs(depth[j] - thermal[i]) <= 1 / 60 + 1e-12  # nearest of a 33 ms grid
    assert stats.max_abs_skew_ms <= 1000 / 60 + 1e-9
    assert "pairs 87, dropped 0 of 87 thermal frames" in stats.summary()


def test_gap_in_depth_drops_thermal_frames() -> None:
    depth = np.concatenate([np.arange(0, 1, 1 / 30), np.arange(2, 3, 1 / 30)])
    thermal = np.arange(0, 2.95, 1 / 8.7)
    pairs, stats = pair_times(depth, thermal, max_skew_s=0.020)
    last_before, first_after = depth[depth < 1.5].max(), depth[depth > 1.5].min()
    in_gap = int(np.sum((thermal > last_before + 0.020) & (thermal < first_after - 0.020)))
    assert in_gap > 5
    assert stats.dropped == in_gap
    assert stats.pairs == len(thermal) - in_gap == len(pairs)


def test_threshold_is_inclusive_and_validated() -> None:
    pairs, stats = pair_times([0.0], [0.0199, 0.0201], max_skew_s=0.020)
    assert pairs == [(0, 0)] and stats.dropped == 1
    with pytest.raises(ValueError, match="max_skew_s"):
        pair_times([0.0], [0.0], max_skew_s=-1)
    with pytest.raises(ValueError, match="must not decrease"):
        pair_times([1.0, 0.0], [0.0])


def online(
    depth: list[float], thermal: list[float], order: list[bool], max_skew_s: float
) -> tuple[list[tuple[int, int]], int]:
    pairer = StreamPairer(max_skew_s, history_s=10.0)
    di = ti = 0
    out = []
    for take_depth in order:
        if take_depth and di < len(depth):
            out += pairer.add_depth(DepthFrame(EMPTY_D, depth[di], di))
            di += 1
        elif ti < len(thermal):
            out += pairer.add_thermal(ThermalFrame(EMPTY_D, thermal[ti], ti, TELEM))
            ti += 1
    while di < len(depth):
        out += pairer.add_depth(DepthFrame(EMPTY_D, depth[di], di))
        di += 1
    while ti < len(thermal):
        out += pairer.add_thermal(ThermalFrame(EMPTY_D, thermal[ti], ti, TELEM))
        ti += 1
    out += pairer.flush()
    assert [m.pair.index for m in out] == list(range(len(out)))
    assert all(m.pair.depth is m.depth.depth for m in out)
    return [(round(m.depth.time_s * 1e6), round(m.thermal.time_s * 1e6)) for m in out], (
        pairer.stats.dropped
    )


times = st.lists(st.floats(0, 5, allow_nan=False), max_size=60).map(sorted)


@settings(max_examples=150, deadline=None)
@given(depth=times, thermal=times, order=st.lists(st.booleans(), max_size=120))
def test_online_pairing_equals_the_reference(
    depth: list[float], thermal: list[float], order: list[bool]
) -> None:
    max_skew = 0.05
    got, dropped = online(depth, thermal, order, max_skew)
    pairs, stats = pair_times(depth, thermal, max_skew)
    want = [(round(depth[j] * 1e6), round(thermal[i] * 1e6)) for j, i in pairs]
    assert got == want
    assert dropped == stats.dropped
