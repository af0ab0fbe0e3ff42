"""The fusion pipeline end to end on the simulated rig: temperatures, hotspots in 3D, flags,
settings, outputs, and `thermodepth run` (live, recorded, replayed)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from thermodepth.cli import app
from thermodepth.compensation import Flag, PaperModel, save_model
from thermodepth.errors import InputError
from thermodepth.evaluation import Generalisation
from thermodepth.figures import overlay_rgb, plot_overlay
from thermodepth.frames import FramePair
from thermodepth.io.pointcloud import read_ply, write_ply
from thermodepth.measure import hotspot_box_on_depth, roi_stats
from thermodepth.pipeline import (
    HotspotSettings,
    Pipeline,
    PixelFlag,
    RadiometrySettings,
    RegistrationSettings,
    RoiSettings,
    Settings,
)
from thermodepth.registration import Reason, Registration
from thermodepth.schema import PlanckSchema
from thermodepth.sim import Rig, camera_pose, constant_fpa, default_calibration, plate_scene
from thermodepth.sim.cameras import THERMAL_CAMERAS

runner = CliRunner()
CHIP = np.array([0.06, -0.05, -0.003])  # the chip's centre in the world (plate at the origin)


def inspection_rig(distance_m: float, fpa_c: float = 35.0, **kw: object) -> Rig:
    return Rig(
        plate_scene(chip_temp_c=70.0),
        camera_pose(distance_m),
        start_s=1.0,
        fpa=constant_fpa(fpa_c + 273.15),
        **kw,
    )  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def model_path(tmp_path_factory: pytest.TempPathFactory, generalisation: Generalisation) -> Path:
    path = tmp_path_factory.mktemp("model") / "model.json"
    save_model(generalisation.models["radiance"], path)
    return path


def test_pixel_flags_extend_the_compensation_flags() -> None:
    for f in Flag:
        assert PixelFlag[f.name].value == f.value
    assert not (PixelFlag.NO_DISTANCE | PixelFlag.BAD_COUNTS | PixelFlag.SHUTTER) & 0b1111


def test_inspection_frame_at_half_a_metre() -> None:
    rig = inspection_rig(0.5)
    pipe = Pipeline(
        Settings(
            hotspots=HotspotSettings(threshold_c=50.0),
            rois=[RoiSettings(name="plate", depth_range_m=(0.45, 0.55))],
        ),
        rig.calibration,
    )
    frame = pipe.process(rig.frame())
    assert frame.temp_thermal_c.shape == (120, 160) and frame.temp_depth_c.shape == (720, 1280)
    h = frame.hotspots[0]
    assert h.resolvable and h.max_c == pytest.approx(70.0, abs=0.5)
    truth_centre = rig.depth_from_world.apply(CHIP)
    assert np.linalg.norm(np.array(h.centroid_m) - truth_centre) < 0.01
    assert h.distance_m == pytest.approx(np.linalg.norm(truth_centre), abs=0.01)
    # 2 x 2 cm chip = 4 cm^2; the region above 50 C includes some of the optics' halo
    assert 4e-4 < h.area_m2 < 6e-4
    # its box on the depth image holds the chip's centre and is about the chip's size
    cal = rig.calibration
    box = hotspot_box_on_depth(h, frame.z_thermal_m, cal.thermal, cal.depth, cal.thermal_from_depth)
    assert box is not None
    cu, cv = cal.depth.project(truth_centre)
    chip_px = 0.02 * cal.depth.fx / truth_centre[2]
    assert box[0] < cu < box[2] and box[1] < cv < box[3]
    assert chip_px < box[2] - box[0] < 2 * chip_px and chip_px < box[3] - box[1] < 2 * chip_px
    # the plate's ROI (everything 0.45-0.55 m away): its median is the plate's 39 C
    temps = frame.temp_depth_c[(frame.depth_m > 0.45) & (frame.depth_m < 0.55)]
    assert np.nanmedian(temps) == pytest.approx(39.0, abs=0.1)
    assert frame.rois[0].n > 100_000


def test_compensation_in_the_pipeline_removes_the_vox_effect(model_path: Path) -> None:
    plain, compensated = [], []
    for vox in (25.0, 40.0):
        rig = inspection_rig(1.2, fpa_c=vox)
        pair = rig.frame()
        for settings, out in (
            (Settings(), plain),
            (Settings(compensation=model_path), compensated),
        ):
            frame = Pipeline(settings, rig.calibration).process(pair)
            plate = frame.temp_thermal_c[55:62, 70:78]  # inside the plate, away from the chip
            out.append(float(np.median(plate)))
    assert plain[1] - plain[0] > 2.0  # the VOx effect: ~2.7 C over 25 -> 40 C
    assert compensated == pytest.approx([39.0, 39.0], abs=0.1)


def test_pipelines_share_a_registration() -> None:
    rig = inspection_rig(1.0)
    pair = rig.frame()
    shared = Registration(rig.calibration)
    a = Pipeline(Settings(), rig.calibration, shared).process(pair)
    b = Pipeline(Settings(), rig.calibration).process(pair)
    np.testing.assert_array_equal(a.temp_depth_c, b.temp_depth_c)
    with pytest.raises(ValueError, match="another calibration or method"):
        Pipeline(Settings(), rig.calibration, Registration(rig.calibration, "paper"))
    other = replace(rig.calibration, depth_scale_m=0.0001)
    with pytest.raises(ValueError, match="another calibration or method"):
        Pipeline(Settings(), other, shared)


def test_reflected_temperature_reaches_every_compensation(model_path: Path, tmp_path: Path) -> None:
    # the plate (emissivity 0.95) reflects 5% of its surroundings: hotter surroundings must
    # lower the temperature read from the same counts, with or without a model
    rig = inspection_rig(1.2)
    pair = rig.frame()
    save_model(PaperModel.preset_2022(), tmp_path / "paper.json")
    for model in (None, tmp_path / "paper.json", model_path):
        median = []
        for reflected_c in (None, 60.0):
            radiometry = RadiometrySettings(reflected_temp_c=reflected_c)
            frame = Pipeline(
                Settings(compensation=model, radiometry=radiometry), rig.calibration
            ).process(pair)
            median.append(float(np.median(frame.temp_thermal_c[55:62, 70:78])))
        assert median[0] - median[1] == pytest.approx(2.2, abs=0.3), model


def test_radiance_model_refuses_other_radiometry(model_path: Path) -> None:
    cal = default_calibration()
    for radiometry in (
        RadiometrySettings(method="thermimage"),
        RadiometrySettings(planck=PlanckSchema(R=1e5, B=1400, F=1, O=6000)),
    ):
        with pytest.raises(InputError, match="carries its own radiometry"):
            Pipeline(Settings(compensation=model_path, radiometry=radiometry), cal)
    # naming the model's own constants is fine
    Pipeline(
        Settings(compensation=model_path, radiometry=RadiometrySettings(planck="paper2022")), cal
    )


def test_vox_outside_the_model_is_flagged_on_measurements(model_path: Path) -> None:
    rig = inspection_rig(1.0, fpa_c=55.0)
    pipe = Pipeline(
        Settings(
            compensation=model_path,
            hotspots=HotspotSettings(threshold_c=50),
            rois=[
                RoiSettings(name="all", rect=(0, 0, 1280, 720)),
                RoiSettings(name="corner", rect=(0, 0, 20, 20)),  # outside the thermal view
            ],
        ),
        rig.calibration,
    )
    frame = pipe.process(rig.frame())
    assert frame.hotspots and all(h.flags & Flag.VOX_OUTSIDE for h in frame.hotspots)
    assert frame.rois[0].flags & Flag.VOX_OUTSIDE
    assert frame.rois[1].n == 0 and frame.rois[1].flags == 0


def test_the_depth_grid_is_sampled_once_and_only_when_asked_for() -> None:
    rig = inspection_rig(1.0)
    pair = rig.frame()
    calls: list[bool] = []

    class Counting(Registration):
        def thermal_to_depth(self, *args: Any, **kwargs: Any) -> Any:
            calls.append("regions" in kwargs)
            return super().thermal_to_depth(*args, **kwargs)

    reg = Counting(rig.calibration)
    frame = Pipeline(Settings(), rig.calibration, registration=reg).process(pair)
    assert calls == [] and frame.hotspots  # measured without it
    values, reason = reg.thermal_to_depth(
        pair.depth, frame.temp_thermal_c, nearest=reg.depth_to_thermal(pair.depth)
    )
    calls.clear()
    assert np.array_equal(frame.temp_depth_c, values, equal_nan=True)
    assert np.array_equal(frame.reason_depth, reason) and frame.points()[0].size
    assert calls == [False]  # once, for all three
    rois = [RoiSettings(name="all", rect=(0, 0, 1280, 720))]
    calls.clear()
    frame = Pipeline(Settings(rois=rois), rig.calibration, registration=reg).process(pair)
    assert calls == [True]  # the ROIs are summed while sampling
    assert np.array_equal(frame.temp_depth_c, values, equal_nan=True) and calls == [True]


@pytest.mark.parametrize(
    ("method", "interpolation"),
    [("reproject", "nearest"), ("reproject", "bilinear"), ("paper", "nearest")],
)
def test_roi_statistics_are_those_of_the_whole_mask(method: str, interpolation: str) -> None:
    # ROIs summed row by row while the registration samples (the paper's method: in a pass
    # of their own) equal numpy over the full-image mask, bit for bit
    rig = inspection_rig(1.0)
    rois = [
        RoiSettings(name="rect", rect=(500, 250, 780, 470)),
        RoiSettings(name="poly", polygon=[(520, 260), (760, 300), (600, 460)]),
        RoiSettings(name="range", depth_range_m=(0.5, 1.5)),
    ]
    registration = RegistrationSettings(method=method, interpolation=interpolation)
    pipe = Pipeline(Settings(rois=rois, registration=registration), rig.calibration)
    frame = pipe.process(rig.frame())
    shape = rig.calibration.depth.shape
    # the thermal pixel each depth pixel sees, from the registration's own map
    index = np.empty(shape, np.int32)
    near = pipe.registration.depth_to_thermal(frame.depth)
    pipe.registration.thermal_to_depth(
        frame.depth, frame.temp_thermal_c, interpolation, nearest=near, thermal_index=index
    )
    flags = frame.flags_thermal.ravel()
    for got, roi in zip(frame.rois, pipe.rois, strict=True):
        mask = roi.mask(shape, frame.depth_m)
        seen = index[mask]
        want = roi_stats(roi.name, frame.temp_depth_c, mask, flags[seen[seen >= 0]])
        assert got.n > 1000
        assert got == want


def test_shutter_frame_and_bad_counts_keep_the_stream_going() -> None:
    rig = inspection_rig(1.0)
    told: list[str] = []
    pipe = Pipeline(
        Settings(rois=[RoiSettings(name="all", rect=(0, 0, 1280, 720))]),
        rig.calibration,
        warn=told.append,
    )
    pair = rig.frame()
    shut = replace(pair, telemetry=replace(pair.telemetry, ffc_state=2))
    f = pipe.process(shut)
    assert f.in_ffc and np.isnan(f.temp_thermal_c).all() and not f.hotspots
    assert np.all(f.flags_thermal & PixelFlag.SHUTTER)
    bad = replace(pair, thermal=np.full((120, 160), 65535, np.uint16))  # above 14 bits
    f = pipe.process(bad)
    assert np.isnan(f.temp_thermal_c).all() and np.all(f.flags_thermal & PixelFlag.BAD_COUNTS)
    # a whole frame beyond the stated kind is told once, in one line naming the frame
    pipe.process(bad)
    assert len(told) == 1 and told[0].startswith(f"frame {pair.index}: the thermal values")
    assert "beyond the 14-bit range" in told[0]
    assert np.isnan(f.temp_depth_c).all()
    assert f.rois[0].n == 0 and f.rois[0].flags & PixelFlag.BAD_COUNTS  # says why it is empty
    # a corrupt frame (random values: a quarter of them look like counts) is not trusted
    noise = np.random.default_rng(3).integers(0, 65536, (120, 160), dtype=np.uint16)
    f = Pipeline(Settings(hotspots=HotspotSettings(threshold_c=30.0)), rig.calibration,
                 warn=told.append).process(replace(pair, thermal=noise))  # fmt: skip
    assert np.isnan(f.temp_thermal_c).all() and not f.hotspots and not f.events
    assert np.all(f.flags_thermal & PixelFlag.BAD_COUNTS)
    good = pipe.process(rig.frame())
    assert np.isfinite(good.temp_thermal_c).mean() > 0.99


def test_thermal_pixels_without_depth_are_flagged() -> None:
    rig = inspection_rig(1.0)
    pair = rig.frame()
    depth = pair.depth.copy()
    depth[:, :640] = 0  # the left half of the depth image is lost
    f = Pipeline(Settings(), rig.calibration).process(replace(pair, depth=depth))
    no_depth = (f.flags_thermal & PixelFlag.NO_DISTANCE).astype(bool)
    assert 0.3 < no_depth.mean() < 0.7
    assert np.isfinite(f.temp_thermal_c[no_depth]).all()  # computed at the fallback distance
    assert np.all(f.reason_depth[:, :640] == Reason.INVALID_DEPTH)


def test_calibration_that_does_not_match_the_frames() -> None:
    rig = inspection_rig(1.0)
    pair = rig.frame()
    small = FramePair(
        pair.depth[:480, :640].copy(),
        pair.thermal,
        pair.depth_time_s,
        pair.thermal_time_s,
        pair.telemetry,
        7,
    )
    with pytest.raises(
        InputError,
        match="frame 7: the depth image is 640x480 but the calibration's depth camera is 1280x720",
    ):
        Pipeline(Settings(), rig.calibration).process(small)
    # raw counts whose telemetry says TLinear (kelvin x 100): no temperature, told in one line
    kelvin = replace(pair, telemetry=replace(pair.telemetry, tlinear=True))
    told: list[str] = []
    f = Pipeline(Settings(), rig.calibration, warn=told.append).process(kelvin)
    assert np.all(f.flags_thermal & PixelFlag.BAD_COUNTS) and not f.hotspots
    assert len(told) == 1 and "read as kelvin x 100 give a median of 8" in told[0]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("emisivity: 0.9\n", "emisivity: unknown key"),
        (
            "radiometry: {emissivity: 1.5}\n",
            r"radiometry.emissivity: outside 0 < emissivity <= 1 \(got 1.5\)$",
        ),
        ("hotspots: {threshold_c: hot}\n", "hotspots.threshold_c: Input should be a valid number"),
        (
            "radiometry: {ambient_temp_c: -300}\n",
            r"radiometry.ambient_temp_c: outside -273.15 < T <= 5000 C \(got -300\)$",
        ),
        ("alarms: [{name: a, above_c: 1e6}]\n", "alarms.0.above_c: Input should be less than"),
        ("fallback_distance_m: 1e300\n", "fallback_distance_m: Input should be less than"),
        (
            "rois: [{name: a, rect: [0, 0, 10, 10], depth_range_m: [1, 2]}]\n",
            "rois.0: give exactly one of",
        ),
        ("alarms: [{name: x, above_c: 60, what: pump}]\n", "what='pump' is neither 'hotspot'"),
        (
            "rois: [{name: r, rect: [720, 420, 560, 300]}]\n",
            r"rois.0: rect \[720, 420, 560, 300\]: expected u0 < u1 and v0 < v1 \(pixels\)$",
        ),
        ("rois: [{name: p, polygon: [[0, 0], [10, 10], [20, 20]]}]\n", "encloses no area$"),
        (
            "rois: [{name: d, depth_range_m: [1.5, 1.2]}]\n",
            r"depth_range_m \[1.5, 1.2\]: expected 0 <= near < far \(metres\)$",
        ),
        (
            "rois: [{name: a, rect: [0, 0, 9, 9]}, {name: a, depth_range_m: [1, 2]}]\n",
            ": ROI names must differ: 'a' twice$",
        ),
        ("alarms: [{name: h, above_c: 60}, {name: h, above_c: 65}]\n", "alarm names must differ"),
        (
            "registration: {method: magic}\n",
            r"registration.method: choose from \['paper', 'reproject'\] \(got 'magic'\)",
        ),
    ],
)
def test_bad_settings_are_one_line(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(text)
    with pytest.raises(InputError, match=message) as info:
        Settings.load(path)
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("shape", "inside"),
    [
        ("rect: [-100, -100, -10, -10]", False),  # a negative end once meant 'from the far edge'
        ("rect: [5000, 5000, 6000, 6000]", False),
        ("polygon: [[5000, 5000], [6000, 5000], [6000, 6000]]", False),
        ("rect: [-100, -100, 10, 20]", True),  # partly inside: the part inside
    ],
)
def test_an_roi_outside_the_depth_image_is_refused(
    tmp_path: Path, shape: str, inside: bool
) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(f"rois: [{{name: spot, {shape}}}]\n")
    cal = default_calibration()
    if inside:
        pipe = Pipeline(Settings.load(path), cal)
        assert pipe.rois[0].mask(cal.depth.shape).sum() == 10 * 20
        return
    with pytest.raises(InputError) as info:
        Pipeline(Settings.load(path), cal)
    assert str(info.value) == (
        f"{path}: rois.0: 'spot' lies outside the 1280x720 depth image (u 0..1279, v 0..719)"
    )


def test_settings_paths_are_relative_to_the_file(tmp_path: Path, model_path: Path) -> None:
    rig = inspection_rig(1.0)
    rig.calibration.save(tmp_path / "cal.yaml")
    (tmp_path / "model.json").write_bytes(model_path.read_bytes())
    (tmp_path / "s.yaml").write_text("calibration: cal.yaml\ncompensation: model.json\n")
    pipe = Pipeline(Settings.load(tmp_path / "s.yaml"))
    assert pipe.model is not None and pipe.calibration.thermal == rig.calibration.thermal


def test_point_cloud_and_overlay(tmp_path: Path) -> None:
    rig = inspection_rig(0.5, with_ir=True)
    frame = Pipeline(Settings(hotspots=HotspotSettings(threshold_c=50)), rig.calibration).process(
        rig.frame()
    )
    pts, temps = frame.points()
    ok = frame.reason_depth == Reason.OK
    assert len(pts) == int(ok.sum()) > 200_000
    v, u = np.nonzero(ok)  # the cached rays give what deproject gives, bit for bit
    assert np.array_equal(
        pts, rig.calibration.depth.deproject(np.stack([u, v], -1), frame.depth_m[ok])
    )
    assert np.array_equal(frame.points(7)[0], pts[::7])
    path = write_ply(tmp_path / "cloud.ply", pts, temps)
    assert b"property float temperature" in path.read_bytes()[:400]
    back_pts, back_t = read_ply(path)
    np.testing.assert_allclose(back_pts, pts, atol=1e-6)
    np.testing.assert_array_equal(back_t, temps)
    hot = back_pts[back_t > 60]  # the chip: ~0.5 m in front, 6 cm right, 5 cm up
    np.testing.assert_allclose(np.median(hot, axis=0), rig.depth_from_world.apply(CHIP), atol=0.01)
    png = plot_overlay(frame, tmp_path / "overlay.png")
    import cv2

    img = cv2.imread(str(png))
    assert img.shape[0] > 700 and img.shape[1] > 1280
    assert img.std() > 10  # not blank


def test_pixels_without_a_temperature_never_look_like_one() -> None:
    from matplotlib import colormaps

    rig = inspection_rig(1.0)
    frame = Pipeline(Settings(), rig.calibration).process(rig.frame())
    rgb = overlay_rgb(frame, (20.0, 70.0))
    inferno = colormaps["inferno"](np.linspace(0, 1, 256))[:, :3]
    assert np.all(inferno[:, 1] <= inferno[:, 0] + 0.015)  # its green never leads its red
    reason = frame.reason_depth
    hidden = rgb[reason == Reason.OCCLUDED]
    no_depth = rgb[reason == Reason.INVALID_DEPTH]
    outside = rgb[reason == Reason.OUTSIDE]
    assert len(hidden) > 1000 and len(no_depth) > 1000 and len(outside) > 1000
    # hidden: green stripes on half of it; no depth: teal; outside: light neutral grey
    assert 0.4 < np.mean(hidden[:, 1] > hidden[:, 0] + 0.2) < 0.6
    assert np.all(no_depth[:, 1] > no_depth[:, 0] + 0.2)
    assert np.all(np.ptp(outside, axis=1) < 1e-6) and outside.min() >= 0.5
    seen = rgb[reason == Reason.OK]
    assert np.all(seen[:, 1] <= seen[:, 0] + 0.015)  # a temperature over grey: never green


def test_run_live_with_record_then_replay_gives_the_same_results(tmp_path: Path) -> None:
    settings = tmp_path / "s.yaml"
    settings.write_text(
        "hotspots: {threshold_c: 50}\n"
        "rois: [{name: plate, rect: [560, 300, 720, 420]}]\n"
        "alarms: [{name: chip, above_c: 60, for_frames: 2}]\n"
    )
    live = runner.invoke(
        app,
        [
            "run",
            "--source",
            "sim",
            "--settings",
            str(settings),
            "--frames",
            "6",
            "--record",
            str(tmp_path / "s.zarr"),
            "-o",
            str(tmp_path / "live"),
        ],
    )
    assert live.exit_code == 0, live.output
    assert "ALARM chip" in live.output and "shutter closed" in live.output
    replay = runner.invoke(
        app,
        [
            "run",
            "--source",
            f"recording:{tmp_path / 's.zarr'}",
            "--settings",
            str(settings),
            "-o",
            str(tmp_path / "replay"),
            "--quiet",
        ],
    )
    assert replay.exit_code == 0, replay.output
    assert "calibration" not in live.output + replay.output  # the settings give none
    a = (tmp_path / "live" / "measurements.jsonl").read_text()
    b = (tmp_path / "replay" / "measurements.jsonl").read_text()
    assert a == b and len(a.splitlines()) == 6
    alarms = [json.loads(x) for x in (tmp_path / "live" / "alarms.jsonl").read_text().splitlines()]
    assert [e["event"] for e in alarms] == ["alarm"] and alarms[0]["value_c"] > 60
    rows = (tmp_path / "live" / "hotspots.csv").read_text().splitlines()
    assert rows[0].startswith("frame,thermal_time_s,vox_temp_c,label,max_c")
    assert len(rows) == 1 + 3  # the chip in each of the 3 frames after the power-on FFC
    assert float(rows[1].split(",")[9]) == pytest.approx(1.0, abs=0.02)  # distance_m


def test_run_stops_cleanly_on_ctrl_c(tmp_path: Path) -> None:
    from thermodepth.app.run import RunOptions, run
    from thermodepth.io.recording import Recording
    from thermodepth.sinks import CallbackSink

    seen = []

    def interrupt_after_four(frame: object) -> None:
        seen.append(frame)
        if len(seen) == 4:
            raise KeyboardInterrupt

    result = run(RunOptions(record=tmp_path / "r.zarr"), [CallbackSink(interrupt_after_four)])
    assert result.stopped == "interrupted" and result.frames == 4
    assert Recording(tmp_path / "r.zarr").n_pairs == 4  # every fused pair was recorded


def test_each_frames_measurements_are_on_disk_when_it_ends(tmp_path: Path) -> None:
    from thermodepth.app.run import RunOptions, run
    from thermodepth.sinks import CallbackSink

    on_disk = []

    def count_lines(frame: object) -> None:  # what a kill -9 right now would leave
        on_disk.append(len((tmp_path / "m" / "measurements.jsonl").read_text().splitlines()))

    run(RunOptions(frames=3, out_dir=tmp_path / "m"), [CallbackSink(count_lines)])
    assert on_disk == [1, 2, 3]


def test_run_says_when_the_source_keeps_its_own_calibration(tmp_path: Path) -> None:
    default_calibration().save(tmp_path / "mine.yaml")
    (tmp_path / "s.yaml").write_text(f"calibration: {tmp_path / 'mine.yaml'}\n")
    res = runner.invoke(
        app, ["run", "--settings", str(tmp_path / "s.yaml"), "--frames", "1", "--quiet"]
    )
    assert res.exit_code == 0, res.output
    assert "sim: the simulated rig keeps its own calibration; the one given is not" in (
        " ".join(res.output.split())
    )


def test_run_without_calibration_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "s.yaml").write_text("calibration: nope.yaml\n")
    res = runner.invoke(app, ["run", "--settings", str(tmp_path / "s.yaml")])
    assert res.exit_code == 2 and "nope.yaml: cannot read" in res.output


# -- run with cameras: single streams, pairing, recording attributes -------------------------


class SimCamera:
    """One stream of the simulated rig as a live camera would give it (``stream``: depth or
    thermal); the depth camera also carries the device's own depth section."""

    live = True

    def __init__(self, stream: str, n: int, device_depth: dict | None = None) -> None:  # type: ignore[type-arg]
        self.name, self.stream, self.n = f"sim-{stream}", stream, n
        self.device_depth = device_depth
        self.closed = False

    def __iter__(self):  # type: ignore[no-untyped-def]
        from thermodepth.frames import DepthFrame, ThermalFrame

        rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(1.0))
        for i, p in enumerate(rig.frames(self.n)):
            if self.stream == "depth":
                yield DepthFrame(p.depth, p.depth_time_s, i)
            else:
                yield ThermalFrame(p.thermal, p.thermal_time_s, i, p.telemetry)

    def close(self) -> None:
        self.closed = True


def paired_sim(n: int, device_depth: dict | None = None, max_skew_s: float = 0.02):  # type: ignore[no-untyped-def, type-arg]
    from thermodepth.sources.paired import PairedSource

    return PairedSource(
        SimCamera("depth", n, device_depth), SimCamera("thermal", n), None, max_skew_s, 10.0
    )


def test_run_with_a_single_camera_is_refused_before_recording(tmp_path: Path) -> None:
    from thermodepth.frames import DepthFrame
    from thermodepth.io.recording import RecordingWriter

    depth_only = tmp_path / "depth.zarr"
    with RecordingWriter(depth_only) as w:
        w.add(DepthFrame(np.zeros((720, 1280), np.uint16), 0.0, 0))
    settings = tmp_path / "s.yaml"
    settings.write_text(f"calibration: {Path(__file__).parents[1] / 'examples/calibration.yaml'}\n")
    out = tmp_path / "x.zarr"
    res = runner.invoke(
        app,
        [
            "run",
            "--source",
            f"recording:{depth_only}",
            "--settings",
            str(settings),
            "--record",
            str(out),
        ],
    )
    assert res.exit_code == 2, res.output
    assert res.output.strip() == (
        f"error: recording:{depth_only}: gives depth only; FramePairs need a depth and a "
        "thermal camera (use realsense+lepton, sim or recording:PATH)"
    )
    assert not out.exists()


def test_run_session_refuses_a_single_camera_and_closes_it(tmp_path: Path) -> None:
    from thermodepth.session import run_session
    from thermodepth.sinks import RecorderSink
    from thermodepth.sources.paired import StreamSource

    camera = SimCamera("depth", 2)
    pipeline = Pipeline(Settings(), default_calibration())
    with pytest.raises(InputError, match="sim-depth: gives depth only"):
        sinks = [RecorderSink(tmp_path / "x.zarr")]
        run_session(StreamSource(camera, "depth"), pipeline, sinks=sinks)
    assert camera.closed and not (tmp_path / "x.zarr").exists()


def test_run_prints_pairing_and_records_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, model_path: Path
) -> None:
    import thermodepth.sources
    from thermodepth.io.recording import Recording

    opened: dict = {}  # type: ignore[type-arg]

    def open_paired_sim(spec: str, calibration: object = None, **kw: object) -> object:
        opened.update(kw)
        return paired_sim(3, max_skew_s=float(kw["max_skew_s"]))  # type: ignore[arg-type]

    monkeypatch.setattr(thermodepth.sources, "open_source", open_paired_sim)
    settings = tmp_path / "s.yaml"
    cal = Path(__file__).parents[1] / "examples" / "calibration.yaml"
    settings.write_text(f"calibration: {cal}\ncompensation: {model_path}\n")
    res = runner.invoke(
        app,
        [
            "run",
            "--source",
            "realsense+lepton",
            "--settings",
            str(settings),
            "--quiet",
            "--max-skew-ms",
            "18",  # the rig's skews are at most 16.7 ms
            "--thermal-latency-ms",
            "12",
            "--record",
            str(tmp_path / "r.zarr"),
        ],
    )
    assert res.exit_code == 0, res.output
    assert opened["max_skew_s"] == 0.018 and opened["thermal_latency_s"] == 0.012
    assert "pairing: pairs 3, dropped 0 of 3 thermal frames" in res.output
    rec = Recording(tmp_path / "r.zarr")
    assert rec.attrs["pairing"]["pairs"] == 3 and rec.attrs["stopped"] == "end"
    assert rec.attrs["source_counters"] == {}
    pipeline = rec.settings["pipeline"]
    assert pipeline["settings_yaml"] == settings.read_text()
    assert pipeline["compensation_sha256"] == hashlib.sha256(model_path.read_bytes()).hexdigest()


def test_replay_uses_the_recorded_device_depth_with_the_users_calibration(
    tmp_path: Path,
) -> None:
    from thermodepth.calibration import Calibration
    from thermodepth.session import record_session
    from thermodepth.sources import open_source

    user = Calibration.load(Path(__file__).parents[1] / "examples" / "calibration.yaml")
    device = {**user.to_dict()["depth"], "cx": 641.25, "depth_scale_m": 0.00025}
    record_session(paired_sim(2, device_depth=device), tmp_path / "d.zarr")  # no calibration
    lines: list[str] = []
    src = open_source(f"recording:{tmp_path / 'd.zarr'}", user, warn=lines.append)
    assert lines == []  # the user's calibration is used: nothing to say
    assert src.calibration is not None
    assert src.calibration.depth.cx == 641.25  # the device's ...
    assert src.calibration.depth_scale_m == 0.00025
    assert src.calibration.thermal == user.thermal  # ... with the user's thermal camera
    # without one of the user's, nothing to fuse with: one line
    res = runner.invoke(app, ["run", "--source", f"recording:{tmp_path / 'd.zarr'}"])
    assert res.exit_code == 2 and "no calibration: give one in the settings" in res.output


# -- any camera: its own temperature as pixels, no sensor temperature, other depth units -------


def test_a_camera_reading_its_own_temperature_measures_as_one_giving_counts(
    generalisation: Generalisation,
) -> None:
    # the same scene, lens and sensor state through a sensor giving 14-bit counts and one
    # giving TLinear (a Lepton 3.5's 0.01 K): the same temperatures, to the quantisation
    model = generalisation.models["radiance"]
    got = {}
    for camera in ("lepton3", "lepton3.5"):
        sensor = THERMAL_CAMERAS[camera].sensor
        cal = replace(default_calibration(), thermal_output=sensor.output)
        rig = inspection_rig(1.0, calibration=cal, lepton=sensor, seed=3)
        pair = rig.frame()
        assert pair.telemetry.tlinear == (camera == "lepton3.5")
        got[camera] = Pipeline(Settings(), rig.calibration, model=model).process(pair)
    a, b = got["lepton3"].temp_thermal_c, got["lepton3.5"].temp_thermal_c
    assert np.nanmedian(np.abs(a - b)) < 0.01  # noise draws alike, 0.01 K steps
    assert np.nanmax(np.abs(a - b)) < 0.05
    assert got["lepton3.5"].hotspots[0].max_c == pytest.approx(
        got["lepton3"].hotspots[0].max_c, abs=0.05
    )


def test_frames_without_a_sensor_temperature_are_compensated_at_the_models_reference(
    generalisation: Generalisation,
) -> None:
    model = generalisation.models["radiance"]  # fitted with the VOx temperature
    rig = Rig.of_cameras(plate_scene(39.0), camera_pose(1.0), "p2pro", "848x480", start_s=1.0)
    pair = rig.frame()
    assert np.isnan(pair.telemetry.fpa_temp_k)
    f = Pipeline(Settings(), rig.calibration, model=model).process(pair)
    assert np.all(f.flags_thermal & PixelFlag.NO_VOX)
    assert np.isnan(f.vox_temp_c) and np.isfinite(f.temp_thermal_c).mean() > 0.99
    at_reference = model.from_counts(
        pair.thermal.astype(np.float64),
        model.vox_reference_c,
        f.range_thermal_m,
        Pipeline(Settings(), rig.calibration, model=model).radiometry_of(pair),
    ).temp_c
    seen = np.isfinite(f.range_thermal_m)  # the others at the fallback distance
    assert seen.mean() > 0.9
    assert np.allclose(f.temp_thermal_c[seen], at_reference[seen], atol=1e-4)
    plain = Pipeline(Settings(), rig.calibration).process(pair)  # physics only: no VOx used
    assert not np.any(plain.flags_thermal & PixelFlag.NO_VOX)


def test_depth_in_tenths_of_millimetres_measures_the_same() -> None:
    # a D405 counts 0.1 mm: nothing may assume the D435's 1 mm
    rig = inspection_rig(1.0)
    fine = replace(rig.calibration, depth_scale_m=0.0001)
    rig_fine = inspection_rig(1.0, calibration=fine)
    coarse, tenths = rig.frame(), rig_fine.frame()
    assert np.median(tenths.depth[tenths.depth > 0]) > 9000
    a = Pipeline(Settings(), rig.calibration).process(coarse)
    b = Pipeline(Settings(), fine).process(tenths)
    assert np.nanmedian(np.abs(a.range_thermal_m - b.range_thermal_m)) < 0.001
    assert a.hotspots[0].distance_m == pytest.approx(b.hotspots[0].distance_m, abs=0.002)
    assert a.hotspots[0].max_c == pytest.approx(b.hotspots[0].max_c, abs=0.05)


def test_an_roi_under_its_own_emissivity_reads_as_the_whole_frame_would() -> None:
    # a painted cabinet and a bare busbar in one view: the ROI's own emissivity and
    # reflected temperature give its statistics exactly as settings with them for the whole
    # frame would, and the other ROIs and the hotspots are untouched
    rig = inspection_rig(1.0)
    pair = rig.frame()
    rect = (560, 280, 720, 440)
    own = Settings(
        rois=[
            RoiSettings(name="plate", rect=rect),
            RoiSettings(name="bare", rect=rect, emissivity=0.6, reflected_temp_c=30.0),
        ]
    )
    whole = Settings(
        radiometry=RadiometrySettings(emissivity=0.6, reflected_temp_c=30.0),
        rois=[RoiSettings(name="bare", rect=rect)],
    )
    f = Pipeline(own, rig.calibration).process(pair)
    g = Pipeline(whole, rig.calibration).process(pair)
    plain, bare = f.rois
    assert bare == replace(g.rois[0], name="bare")
    assert bare.mean_c > plain.mean_c + 4  # the same counts read as a poorer emitter
    assert plain == Pipeline(Settings(rois=[own.rois[0]]), rig.calibration).process(pair).rois[0]
