"""Line and isotherm ROIs in real units on the simulated rig, against the scene's truth: a
line's length on a tilted plate and where its hottest point is, an isotherm's area on a plate
tilted 0/30/50 deg at 0.7/1.5/2.5 m; the area alarm rule, the band's colour, the files, the
settings' one-line errors."""

from __future__ import annotations

import csv
import json
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from thermodepth.alarms import AlarmRule, AlarmTracker, event_line
from thermodepth.errors import InputError
from thermodepth.figures import overlay_rgb
from thermodepth.frames import FramePair
from thermodepth.io.measurements import MeasurementWriter
from thermodepth.isotherms import ISOTHERM_RGB
from thermodepth.monitor.live import overlay_image
from thermodepth.palettes import PALETTES, palette
from thermodepth.pipeline import (
    AlarmSettings,
    FusedFrame,
    Pipeline,
    RegistrationSettings,
    RoiSettings,
    Settings,
)
from thermodepth.sim import Rig, camera_pose, constant_fpa, default_calibration
from thermodepth.sim.scene import Material, Rect, Scene

K = 273.15
EX, EY = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
HOT_M = (0.20, 0.15)  # the hot rectangle on the plate: 300 cm^2
PLATE_C, HOT_C = 40.0, 90.0
STRIP_X_M = 0.08  # the hot strip's centre across the line (world x)


def plate_with(hot: Rect) -> Scene:
    """A 60 cm plate at the world origin (facing -z), a hot rect 1 mm in front of it, and a
    wall 3 m behind."""
    ambient = Material(25 + K, 0.9, 0.6, "ambient")
    plate = Rect(np.zeros(3), EX, EY, 0.3, 0.3, Material(PLATE_C + K, 0.95, 0.3, "plate"),
                 name="plate")  # fmt: skip
    wall = Rect(np.array([0, 0, 3.0]), EX, EY, 8.0, 6.0, ambient, name="wall")
    return Scene((plate, hot, wall), 25 + K, 0.5)


def hot(center: tuple[float, float], size: tuple[float, float]) -> Rect:
    material = Material(HOT_C + K, 0.95, 0.3, "hot")
    c = np.array([center[0], center[1], -0.001])
    return Rect(c, EX, EY, size[0] / 2, size[1] / 2, material, name="hot")


@cache
def isotherm_rig(distance_m: float, tilt_deg: float) -> tuple[Rig, FramePair]:
    rig = Rig(plate_with(hot((0, 0), HOT_M)), camera_pose(distance_m, yaw_deg=tilt_deg),
              start_s=1.0, fpa=constant_fpa(308.15))  # fmt: skip
    return rig, rig.frame()


@cache
def line_rig(distance_m: float, tilt_deg: float) -> tuple[Rig, FramePair]:
    strip = hot((STRIP_X_M, 0), (0.04, 0.2))
    rig = Rig(plate_with(strip), camera_pose(distance_m, yaw_deg=tilt_deg), start_s=1.0,
              fpa=constant_fpa(308.15))  # fmt: skip
    return rig, rig.frame()


def isotherm_settings(**alarm: object) -> Settings:
    rois = [RoiSettings(name="over-65", isotherm={"above_c": 65.0})]  # type: ignore[arg-type]
    alarms = [AlarmSettings(name="big", what="over-65", **alarm)] if alarm else []  # type: ignore[arg-type]
    return Settings(
        rois=rois,
        alarms=alarms,
        registration=RegistrationSettings(interpolation="bilinear"),
    )


@pytest.mark.parametrize("distance_m", [0.7, 1.5, 2.5])
@pytest.mark.parametrize("tilt_deg", [0.0, 30.0, 50.0])
def test_an_isotherms_area_is_the_hot_parts_on_the_surface(
    distance_m: float, tilt_deg: float
) -> None:
    rig, pair = isotherm_rig(distance_m, tilt_deg)
    frame = Pipeline(isotherm_settings(), rig.calibration).process(pair)
    (iso,) = frame.isotherms
    truth_cm2 = HOT_M[0] * HOT_M[1] * 1e4
    assert iso.area_cm2 == pytest.approx(truth_cm2, rel=0.05)
    # its temperatures are an ROI's, for every output that reads the ROIs
    (stats,) = frame.rois
    assert stats.name == "over-65" and stats.n == iso.n > 0
    assert stats.max_c == pytest.approx(HOT_C, abs=2.0)
    # the band is the pixels the truth calls hot, near enough: most of them lie on it
    truth = rig.truth()
    hot_index = rig.scene.index("hot")
    hot_px = np.flatnonzero(truth.depth_rect.ravel() == hot_index)
    shared = np.intersect1d(iso.pixels, hot_px).size
    assert shared >= 0.9 * min(iso.n, hot_px.size)


def line_ends(rig: Rig) -> tuple[tuple[float, float], tuple[float, float]]:
    """The depth pixels (rounded) of two points on the plate 50 cm apart, 3 cm below its
    centre, across the strip."""
    inv = rig.pose.inverse()
    ends = [
        rig.calibration.depth.project(inv.apply(np.array([x, 0.03, 0.0]))) for x in (-0.25, 0.25)
    ]
    a, b = (tuple(float(c) for c in np.rint(e)) for e in ends)
    return a, b  # type: ignore[return-value]


def on_plate(rig: Rig, px: tuple[float, float]) -> np.ndarray:
    """Where a depth pixel's ray meets the plate (world, m): the truth of that pixel."""
    ray = rig.calibration.depth.deproject(np.array(px, np.float64), 1.0)
    o, p = rig.pose.apply(np.zeros(3)), rig.pose.apply(ray)
    return o + (-o[2] / (p[2] - o[2])) * (p - o)


@pytest.mark.parametrize(("distance_m", "tilt_deg"), [(0.7, 40.0), (1.5, 0.0), (2.5, 40.0)])
def test_a_lines_length_and_hottest_point_are_the_scenes(
    distance_m: float, tilt_deg: float
) -> None:
    rig, pair = line_rig(distance_m, tilt_deg)
    start, end = line_ends(rig)
    settings = Settings(rois=[RoiSettings(name="run", line=(start, end))])
    frame = Pipeline(settings, rig.calibration).process(pair)
    (p,) = frame.lines
    a, b = on_plate(rig, start), on_plate(rig, end)
    true_length = float(np.linalg.norm(b - a))
    assert p.length_m == pytest.approx(true_length, rel=0.02)
    assert p.gap_px == 0 and p.n == len(p.pixels)
    # the hottest point is on the strip (4 cm wide), where the truth puts the strip's centre
    true_at = (STRIP_X_M - a[0]) / (b[0] - a[0]) * true_length
    assert p.max_at_m == pytest.approx(true_at, abs=0.02)
    assert p.max_c > PLATE_C + 20
    assert p.max_px is not None and rig.truth().depth_rect[p.max_px[1], p.max_px[0]] == (
        rig.scene.index("hot")
    )
    # positions rise along the line; the JSON line carries the profile
    assert np.all(np.diff(p.distance_m) > 0)
    line = frame.summary()["lines"][0]
    assert line["length_m"] == round(p.length_m, 4) and len(line["temp_c"]) == len(p.pixels)


def test_a_gap_without_depth_is_bridged_and_counted() -> None:
    rig, pair = line_rig(1.5, 0.0)
    start, end = line_ends(rig)
    depth = pair.depth.copy()
    v = int(start[1])
    u0 = int((start[0] + end[0]) / 2)
    depth[v - 3 : v + 4, u0 - 10 : u0 + 10] = 0  # 20 pixels of the line lose their depth
    settings = Settings(rois=[RoiSettings(name="run", line=(start, end))])
    whole = Pipeline(settings, rig.calibration).process(pair).lines[0]
    (p,) = (
        Pipeline(settings, rig.calibration)
        .process(
            FramePair(depth, pair.thermal, pair.depth_time_s, pair.thermal_time_s, pair.telemetry)
        )
        .lines
    )
    assert p.gap_px == 20 and np.isnan(p.distance_m).sum() == 20
    assert np.isnan(p.temp_c[np.isnan(p.distance_m)]).all()
    assert p.length_m == pytest.approx(whole.length_m, rel=0.005)  # the chord spans the gap


def test_an_area_rule_raises_on_the_isotherms_area() -> None:
    rig, pair = isotherm_rig(1.5, 30.0)
    for limit, raised in ((250.0, True), (350.0, False)):
        pipe = Pipeline(isotherm_settings(area_cm2_above=limit), rig.calibration)
        frame = pipe.process(pair)
        assert [e["event"] for e in frame.events] == (["alarm"] if raised else [])
    (event,) = (
        Pipeline(isotherm_settings(area_cm2_above=250.0), rig.calibration).process(pair).events
    )
    assert event["value_c"] is None and event["value_cm2"] == pytest.approx(300, rel=0.05)
    assert event["condition"] == "area above 250 cm2 for 1 frame"
    assert "cm2" in event_line(event)


def test_an_area_rule_clears_when_the_band_shrinks() -> None:
    rule = AlarmRule("big", what="over", area_cm2_above=25.0)
    tracker = AlarmTracker([rule])
    assert tracker.update(0.0, 0, [], [], {"over": 30.0})[0]["event"] == "alarm"
    assert tracker.update(1.0, 1, [], [], {"over": 20.0})[0]["event"] == "clear"
    assert tracker.update(2.0, 2, [], [], {}) == []  # no isotherm measured: nothing raised


def test_the_band_colour_is_no_palettes() -> None:
    colour = np.array(ISOTHERM_RGB)
    for name in PALETTES:
        assert not (palette(name) == colour).all(axis=1).any(), name
        assert np.linalg.norm(palette(name).astype(float) - colour, axis=1).min() > 100, name


def band_frame() -> tuple[Rig, FusedFrame]:
    rig, pair = isotherm_rig(1.5, 30.0)
    settings = isotherm_settings()
    settings = settings.model_copy(
        update={
            "rois": [
                RoiSettings(name="box", rect=(400, 200, 900, 520)),
                RoiSettings(name="over", isotherm={"above_c": 65.0}, within="box"),  # type: ignore[arg-type]
                RoiSettings(name="run", line=((300.0, 360.0), (1000.0, 360.0))),
            ]
        }
    )
    return rig, Pipeline(settings, rig.calibration).process(pair)


def test_the_band_is_drawn_on_the_overlays_and_confined_to_its_roi() -> None:
    _, frame = band_frame()
    iso = frame.isotherms[0]
    v, u = np.divmod(iso.pixels, frame.depth.shape[1])
    assert iso.n > 0 and u.min() >= 400 and u.max() < 900 and v.min() >= 200 and v.max() < 520
    rgb = overlay_rgb(frame, (20.0, 100.0))
    band = np.all(np.rint(rgb * 255) == ISOTHERM_RGB, axis=-1)
    assert np.array_equal(np.flatnonzero(band), iso.pixels)
    bgr = overlay_image(frame, (20.0, 100.0), [])  # the line's ring and label drawn
    magenta = np.flatnonzero(np.all(bgr == ISOTHERM_RGB[::-1], axis=-1))
    # the band, less what the hotspot's box and the labels cover; its label's text besides
    assert magenta.size > 0.8 * iso.n and np.isin(magenta, iso.pixels).mean() > 0.95
    assert [r.name for r in frame.rois] == ["box", "over", "run"]


def test_the_files_hold_the_lines_and_isotherms(tmp_path: Path) -> None:
    _, frame = band_frame()
    with MeasurementWriter(tmp_path) as w:
        w.write(frame)
    (line,) = csv.DictReader((tmp_path / "lines.csv").open())
    (iso,) = csv.DictReader((tmp_path / "isotherms.csv").open())
    p, i = frame.lines[0], frame.isotherms[0]
    assert float(line["length_m"]) == pytest.approx(p.length_m, abs=1e-4)
    assert (int(line["max_u"]), int(line["max_v"])) == p.max_px
    assert float(iso["area_cm2"]) == pytest.approx(i.area_cm2, abs=1e-3)
    summary = json.loads((tmp_path / "measurements.jsonl").read_text())
    assert summary["isotherms"][0]["area_cm2"] == round(i.area_cm2, 3)
    assert summary["lines"][0]["max_px"] == list(p.max_px or ())


def test_no_line_or_isotherm_no_extra_files_or_keys(tmp_path: Path) -> None:
    rig, pair = isotherm_rig(1.5, 30.0)
    frame = Pipeline(Settings(), rig.calibration).process(pair)
    with MeasurementWriter(tmp_path) as w:
        w.write(frame)
    assert not (tmp_path / "lines.csv").exists() and "lines" not in frame.summary()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("rois: [{name: l, line: [[10, 10], [10, 10]]}]\n", r"rois.0: .*its ends are one pixel$"),
        ("rois: [{name: l, line: [[10, 10]]}]\n", r"rois.0.line"),
        ("rois: [{name: i, isotherm: {above_c: -400}}]\n", r"rois.0.isotherm.above_c"),
        ("rois: [{name: i, isotherm: {}}]\n", r"rois.0.isotherm.above_c"),
        (
            "rois: [{name: r, rect: [0, 0, 9, 9], within: x}]\n",
            r"rois.0: .*within is for an isotherm",
        ),
        (
            "rois: [{name: i, isotherm: {above_c: 80}, within: nowhere}]\n",
            r"ROI 'i': within='nowhere' is not a rect, polygon or depth-range ROI \(none\)$",
        ),
        (
            "rois: [{name: l, line: [[0, 0], [9, 9]], emissivity: 0.5}]\n",
            r"rois.0: .*not for a line",
        ),
        (
            "rois: [{name: r, rect: [0, 0, 9, 9]}]\n"
            "alarms: [{name: a, what: r, area_cm2_above: 25}]\n",
            r"alarm 'a': area_cm2_above is for an isotherm ROI \(none\), not 'r'$",
        ),
        (
            "rois: [{name: i, isotherm: {above_c: 80}}]\n"
            "alarms: [{name: a, what: i, area_cm2_above: 0}]\n",
            r"alarms.0.area_cm2_above",
        ),
    ],
)
def test_bad_line_and_isotherm_settings_are_one_line(
    tmp_path: Path, text: str, message: str
) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(text)
    with pytest.raises(InputError, match=message) as info:
        Settings.load(path)
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)


def test_a_line_outside_the_depth_image_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("rois: [{name: far, line: [[5000, 10], [6000, 10]]}]\n")
    with pytest.raises(InputError, match="'far' lies outside the 1280x720 depth image"):
        Pipeline(Settings.load(path), default_calibration())
