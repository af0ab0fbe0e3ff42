"""Measurements: ROI statistics, spots, hotspots in 3D (area from depth), alarms."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from thermodepth.alarms import AlarmRule, AlarmTracker
from thermodepth.camera import Intrinsics, RigidTransform, rotation_from_euler
from thermodepth.measure import (
    DepthRangeRoi,
    PolygonRoi,
    RectRoi,
    RoiStats,
    bounding_box,
    find_hotspots,
    roi_stats,
    spot_at_point,
)
from thermodepth.radiometry import STEFAN_BOLTZMANN

PINHOLE = Intrinsics(160, 120, 150.0, 150.0, 79.5, 59.5)
IDENTITY = RigidTransform.identity("thermal", "depth")


def test_roi_masks_and_stats() -> None:
    shape = (10, 20)
    rect = RectRoi("r", 2, 3, 6, 5).mask(shape)
    assert rect.sum() == 4 * 2 and rect[3, 2] and not rect[5, 2]
    poly = PolygonRoi("p", ((0, 0), (9, 0), (9, 9), (0, 9))).mask(shape)
    assert poly.sum() == 100
    depth = np.full(shape, 2.0)
    depth[:, :5] = 1.0
    depth[0, 0] = np.nan
    near = DepthRangeRoi("d", 0.5, 1.5).mask(shape, depth)
    assert near.sum() == 49  # the NaN pixel is in no range
    temp = np.arange(200, dtype=float).reshape(shape)
    temp[3, 2] = np.nan
    s = roi_stats("r", temp, rect, np.array([0, 2, 0], np.uint8))
    assert s.n == 7 and s.max_c == 85.0 and s.min_c == 63.0 and s.flags == 2
    empty = roi_stats("e", temp, np.zeros(shape, bool))
    assert empty.n == 0 and np.isnan(empty.mean_c)


def test_bounding_box_holds_every_pixel_of_the_mask() -> None:
    shape = (10, 20)
    assert bounding_box(RectRoi("r", 2, 3, 6, 5).mask(shape)) == (slice(3, 5), slice(2, 6))
    poly = PolygonRoi("p", ((4, 1), (12, 6), (5, 8))).mask(shape)
    box = bounding_box(poly)
    assert poly[box].sum() == poly.sum()
    assert poly[box][0].any() and poly[box][-1].any()  # tight on all four sides
    assert poly[box][:, 0].any() and poly[box][:, -1].any()
    one = np.zeros(shape, bool)
    one[9, 19] = True
    assert bounding_box(one) == (slice(9, 10), slice(19, 20))
    none = bounding_box(np.zeros(shape, bool))
    assert np.zeros(shape)[none].size == 0


def _square(temp: float, size: int, bg: float = 25.0, at: tuple[int, int] = (60, 40)) -> np.ndarray:
    img = np.full((120, 160), bg)
    img[at[1] : at[1] + size, at[0] : at[0] + size] = temp
    return img


def test_hotspot_area_on_a_fronto_parallel_plane_is_exact() -> None:
    z = np.full((120, 160), 2.0)
    spots = find_hotspots(_square(80.0, 5), z, 50.0, PINHOLE, IDENTITY, 25.0, 0.95)
    assert len(spots) == 1
    h = spots[0]
    assert h.thermal_px == 25
    # a pinhole pixel covers (Z / fx)^2 on a plane at Z facing the camera
    assert h.area_m2 == pytest.approx(25 * (2.0 / 150.0) ** 2, rel=1e-9)
    assert h.max_c == 80.0 and h.mean_c == 80.0
    assert h.centroid_m[2] == pytest.approx(2.0) and h.resolvable
    t4 = (80 + 273.15) ** 4 - (25 + 273.15) ** 4
    assert h.power_w == pytest.approx(h.area_m2 * 0.95 * STEFAN_BOLTZMANN * t4, rel=1e-9)


def test_hotspot_area_on_a_tilted_plane_grows_by_one_over_cos() -> None:
    # a plane tilted 50 deg about the y axis through (0, 0, 2): Z(x) = 2 + x tan(50 deg)
    tilt = np.radians(50)
    u = np.tile(np.arange(160), (120, 1))
    x = (u - PINHOLE.cx) / PINHOLE.fx
    z = 2.0 / (1 - x * np.tan(tilt))
    h = find_hotspots(_square(80.0, 3, at=(79, 59)), z, 50.0, PINHOLE, IDENTITY, 25.0)[0]
    # near the optical axis the footprint is (Z/f)^2 / cos(tilt)
    assert h.area_m2 == pytest.approx(9 * (2.0 / 150.0) ** 2 / np.cos(tilt), rel=0.02)


def test_small_and_unknown_hotspots() -> None:
    z = np.full((120, 160), 1.0)
    spots = find_hotspots(_square(80.0, 2), z, 50.0, PINHOLE, IDENTITY, 25.0)
    assert not spots[0].resolvable  # 2 x 2 pixels: reads low, flagged
    # a hot blob with a gradient: the 3 x 3 rule looks at its core near the maximum
    img = _square(55.0, 7)
    img[43, 63] = 90.0
    assert not find_hotspots(img, z, 50.0, PINHOLE, IDENTITY, 25.0)[0].resolvable
    nodepth = find_hotspots(
        _square(80.0, 4), np.full((120, 160), np.nan), 50.0, PINHOLE, IDENTITY, 25.0
    )[0]
    assert nodepth.thermal_px == 16 and np.isnan(nodepth.area_m2)
    assert find_hotspots(_square(40.0, 4), z, 50.0, PINHOLE, IDENTITY, 25.0) == []


def test_hotspots_sorted_and_centroid_in_depth_frame() -> None:
    img = _square(60.0, 4, at=(20, 20))
    img[80:84, 120:124] = 90.0
    z = np.full((120, 160), 1.5)
    # the thermal camera 5 cm to the left of the depth camera
    thermal_from_depth = RigidTransform(np.eye(3), np.array([0.05, 0.0, 0.0]), "thermal", "depth")
    spots = find_hotspots(img, z, 50.0, PINHOLE, thermal_from_depth, 25.0)
    assert [round(s.max_c) for s in spots] == [90, 60]
    u, v = 121.5, 81.5  # the hot square's centre
    expected_t = np.array([(u - 79.5) / 150 * 1.5, (v - 59.5) / 150 * 1.5, 1.5])
    np.testing.assert_allclose(spots[0].centroid_m, expected_t - [0.05, 0, 0], atol=1e-9)


def test_spot_at_point() -> None:
    temp = np.full((120, 160), 30.0)
    temp[59, 79] = 70.0
    z = np.full((120, 160), 2.0)
    cam = RigidTransform(rotation_from_euler(0, 0, 0), np.zeros(3), "thermal", "depth")
    centre = [-0.5 / 150 * 2.0, -0.5 / 150 * 2.0, 2.0]  # on pixel (79, 59)'s centre ray
    assert spot_at_point(centre, temp, z, PINHOLE, cam) == 70.0
    assert np.isnan(spot_at_point(np.multiply(centre, 1.5), temp, z, PINHOLE, cam))  # hidden
    assert np.isnan(spot_at_point([5.0, 0.0, 2.0], temp, z, PINHOLE, cam))  # outside the view


def test_alarm_rule_needs_at_least_one_frame() -> None:
    with pytest.raises(ValueError, match="'hot': for_frames must be >= 1, got 0"):
        AlarmRule("hot", 50.0, for_frames=0)


def test_alarm_trips_after_n_frames_and_clears() -> None:
    tracker = AlarmTracker([AlarmRule("hot", 60.0, 3), AlarmRule("roi", 30.0, 1, "plate")])
    z = np.full((120, 160), 1.0)
    hot = find_hotspots(_square(70.0, 4), z, 50.0, PINHOLE, IDENTITY, 25.0)
    cool = find_hotspots(_square(55.0, 4), z, 50.0, PINHOLE, IDENTITY, 25.0)
    roi = [RoiStats("plate", 10, 35.0, 36.0, 34.0, 0.5)]
    events = [
        tracker.update(i * 0.1, i, spots, roi)
        for i, spots in enumerate([hot, hot, hot, hot, cool, hot])
    ]
    kinds = [[(e["event"], e["rule"]) for e in ev] for ev in events]
    assert kinds[0] == [("alarm", "roi")]  # one frame above 30 C suffices
    assert kinds[1] == [] and kinds[2] == [("alarm", "hot")]  # the third frame in a row
    assert kinds[3] == [] and kinds[4] == [("clear", "hot")] and kinds[5] == []
    assert events[2][0]["hotspot"]["max_c"] == 70.0 and events[2][0]["frame"] == 2


def test_the_hotspot_table_says_what_the_measurement_lines_say(tmp_path: Path) -> None:
    """hotspots.csv read by name (csv.DictReader) against measurements.jsonl: every hotspot
    of every frame, each column the field of the same name, to the digits the table keeps."""
    from thermodepth.io.measurements import FILES, HOTSPOT_COLUMNS, MeasurementWriter
    from thermodepth.pipeline import Pipeline, Settings
    from thermodepth.sim import Rig, camera_pose, plate_scene

    rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(1.0))
    pipe = Pipeline(Settings.model_validate({"hotspots": {"threshold_c": 35}}), rig.calibration)
    with MeasurementWriter(tmp_path) as writer:
        for fused in map(pipe.process, rig.frames(6)):
            writer.write(fused)
    frames = [json.loads(x) for x in (tmp_path / FILES[0]).read_text().splitlines()]
    with open(tmp_path / FILES[2], newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
    assert tuple(reader.fieldnames or ()) == HOTSPOT_COLUMNS
    spots = [(f, h) for f in frames for h in f["hotspots"]]
    assert len(spots) >= 3  # the plate, hot, in every frame after the power-on shutter
    assert len(rows) == len(spots)
    for row, (frame, h) in zip(rows, spots, strict=True):
        assert int(row["frame"]) == frame["frame"] and int(row["label"]) == h["label"]
        assert float(row["thermal_time_s"]) == pytest.approx(frame["thermal_time_s"], abs=1e-4)
        assert float(row["vox_temp_c"]) == pytest.approx(frame["vox_temp_c"], abs=0.005)
        for name in ("max_c", "mean_c"):
            assert float(row[name]) == pytest.approx(h[name], abs=5e-4), name
        for name, value in zip(("x_m", "y_m", "z_m"), h["centroid_m"], strict=True):
            assert float(row[name]) == pytest.approx(value, abs=5e-5), name
        assert float(row["distance_m"]) == pytest.approx(h["distance_m"], abs=5e-5)
        assert float(row["area_m2"]) == pytest.approx(h["area_m2"], rel=1e-5)
        assert float(row["power_w"]) == pytest.approx(h["power_w"], rel=1e-3)
        assert int(row["thermal_px"]) == h["thermal_px"]
        assert bool(int(row["resolvable"])) == h["resolvable"]
        assert int(row["flags"]) == h["flags"]
