"""Region sums taken while the registration samples (registration.regions): exact, so equal
to numpy over a whole-image mask whatever the values, masks, depth ranges and flags."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from thermodepth.measure import DepthRangeRoi, PolygonRoi, RectRoi, RoiStats, roi_region, roi_stats
from thermodepth.registration import Reason, Region, Regions, Registration
from thermodepth.registration.kernels import scan_regions
from thermodepth.sim import Rig, camera_pose, plate_scene

SHAPE = (12, 40)
THERMAL = 6 * 8  # thermal pixels the synthetic index points into


class Sampled(NamedTuple):
    """A frame as the registration leaves it: values, reasons, the thermal pixel of each
    depth pixel, and the raw depth."""

    values: np.ndarray
    reason: np.ndarray
    index: np.ndarray
    depth: np.ndarray


def scanned(regions: list[Region], frame: Sampled, flags: np.ndarray | None) -> list[RoiStats]:
    sums = Regions(regions, frame.values.shape[0]).row_sums(flags)
    scan_regions(frame.depth, frame.values, frame.reason, frame.index, sums)
    return [RoiStats.of(str(k), m) for k, m in enumerate(Regions.moments(sums))]


def reference(
    rois: list[RectRoi | PolygonRoi | DepthRangeRoi], frame: Sampled, flags: np.ndarray | None
) -> list[RoiStats]:
    depth = frame.depth
    depth_m = np.where(depth > 0, depth.astype(np.float32) * np.float32(0.001), np.nan)
    out = []
    for k, roi in enumerate(rois):
        mask = roi.mask(frame.values.shape, depth_m)
        seen = np.where(frame.reason == Reason.OK, frame.index, -1)[mask]
        drawn = flags.ravel()[seen[seen >= 0]] if flags is not None else None
        out.append(roi_stats(str(k), frame.values, mask, drawn))
    return out


SPECIAL = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0, 8191.0, -8191.0, 1e6, -1e6], np.float32)


def same(got: list[RoiStats], want: list[RoiStats]) -> bool:
    """Equal field by field, NaN equal to NaN (an empty ROI's statistics)."""
    return len(got) == len(want) and all(
        a.name == b.name and all(x == y or (x != x and y != y) for x, y in zip(
            (a.n, a.mean_c, a.max_c, a.min_c, a.sd_c, a.flags),
            (b.n, b.mean_c, b.max_c, b.min_c, b.sd_c, b.flags),
            strict=True,
        ))
        for a, b in zip(got, want, strict=True)
    )  # fmt: skip


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    special=st.floats(0.0, 0.5),
    scale=st.sampled_from([1.0, 100.0, 1e5]),
    with_flags=st.booleans(),
    cols=st.lists(st.integers(-5, 45), min_size=2, max_size=2),
    rows=st.lists(st.integers(-3, 15), min_size=2, max_size=2),
    range_m=st.lists(st.floats(0.0, 3.5), min_size=2, max_size=2),
)
def test_region_sums_equal_numpy_over_the_mask(
    seed: int,
    special: float,
    scale: float,
    with_flags: bool,
    cols: list[int],
    rows: list[int],
    range_m: list[float],
) -> None:
    rng = np.random.default_rng(seed)
    values = rng.normal(30.0, scale, SHAPE).astype(np.float32)
    odd = rng.random(SHAPE) < special  # NaN, infinities, signed zeros, the clip's edges
    values[odd] = rng.choice(SPECIAL, int(odd.sum()))
    depth = rng.integers(0, 3000, SHAPE).astype(np.uint16)
    depth[rng.random(SHAPE) < 0.1] = 0
    index = rng.integers(0, THERMAL, SHAPE).astype(np.int32)
    reason = np.where(
        depth == 0, Reason.INVALID_DEPTH, np.where(rng.random(SHAPE) < 0.2, Reason.OUTSIDE, 0)
    ).astype(np.uint8)
    values[reason != Reason.OK] = np.nan  # as the registration gives them
    flag_map = None
    if with_flags:  # a few pixels with a bit of their own: the OR tells which were seen
        flag_map = np.zeros(THERMAL, np.uint8)
        flag_map[rng.choice(THERMAL, 4, replace=False)] = [1, 2, 4, 64]
    (u0, u1), (v0, v1), (near, far) = sorted(cols), sorted(rows), sorted(range_m)
    rois: list[RectRoi | PolygonRoi | DepthRangeRoi] = [
        PolygonRoi("poly", ((2.0, 1.0), (35.0, 3.0), (20.0, 11.0))),
        DepthRangeRoi("range", near, far),
    ]
    rect = RectRoi("rect", u0, v0, u1 + 1, v1 + 1)
    if rect.mask(SHAPE).any():  # the pipeline refuses a rectangle outside the image
        rois.append(rect)
    regions = [roi_region(roi, SHAPE, 0.001) for roi in rois]
    frame = Sampled(values, reason, index, depth)
    assert same(scanned(regions, frame, flag_map), reference(rois, frame, flag_map))


def test_an_empty_region_keeps_the_flags_that_say_why() -> None:
    values = np.full(SHAPE, np.nan, np.float32)  # seen, but no temperature (bad counts)
    reason = np.zeros(SHAPE, np.uint8)
    index = np.zeros(SHAPE, np.int32)
    depth = np.full(SHAPE, 1000, np.uint16)
    flag_map = np.full(THERMAL, 32, np.uint8)
    region = roi_region(RectRoi("r", 0, 0, 5, 5), SHAPE, 0.001)
    (stats,) = scanned([region], Sampled(values, reason, index, depth), flag_map)
    assert stats.n == 0 and np.isnan(stats.mean_c) and stats.flags == 32


@pytest.mark.parametrize("interpolation", ["nearest", "bilinear"])
@pytest.mark.parametrize("flagged", ["every fifth pixel", "three rows"])
def test_sums_taken_while_sampling_equal_a_pass_over_the_sampled_image(
    interpolation: str, flagged: str
) -> None:
    rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(0.8))
    reg = Registration(rig.calibration)
    pair = rig.frame()
    shape = rig.calibration.depth.shape
    thermal = np.linspace(20.0, 80.0, pair.thermal.size, dtype=np.float32).reshape(
        pair.thermal.shape
    )
    if flagged == "three rows":  # the sampling gathers flags only for depth rows that reach them
        flag_map = np.zeros(thermal.shape, np.uint8)
        flag_map[[2, 60, 61], ::3] = [[8], [4], [4]]
    else:
        flag_map = (np.arange(thermal.size) % 5 == 0).astype(np.uint8) * 4
    regions = [
        roi_region(RectRoi("r", 300, 100, 900, 600), shape, rig.calibration.depth_scale_m),
        roi_region(DepthRangeRoi("d", 0.5, 0.9), shape, rig.calibration.depth_scale_m),
    ]
    packed = Regions(regions, shape[0])
    during = packed.row_sums(flag_map.reshape(thermal.shape))
    index = np.empty(shape, np.int32)
    values, reason = reg.thermal_to_depth(
        pair.depth, thermal, interpolation, thermal_index=index, regions=during
    )
    after = packed.row_sums(flag_map.reshape(thermal.shape))
    scan_regions(pair.depth, values, reason, index, after)
    assert np.array_equal(during.sums, after.sums) and np.array_equal(during.keys, after.keys)
    moments = Regions.moments(during)
    assert all(m.n > 10_000 for m in moments)
    assert moments[0].flags == (4 if flagged == "every fifth pixel" else 8 | 4)


def test_registration_refuses_sums_of_another_grid() -> None:
    rig = Rig(plate_scene(), camera_pose(1.0))
    reg = Registration(rig.calibration)
    pair = rig.frame()
    wrong = Regions([], 100).row_sums()
    with pytest.raises(ValueError, match="regions must be the row sums of a depth grid of 720"):
        reg.thermal_to_depth(pair.depth, pair.thermal, regions=wrong)


def test_region_masks_are_checked() -> None:
    with pytest.raises(ValueError, match=r"a region's mask must be uint8 \(1, 4\) or \(2, 4\)"):
        Region(slice(0, 2), slice(0, 4), np.ones((3, 4), np.uint8))
