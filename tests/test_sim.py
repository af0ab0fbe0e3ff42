"""The simulated rig: physics, noise models, determinism and exact ground truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from thermodepth.board import BoardSpec
from thermodepth.calibration import Calibration
from thermodepth.camera import RigidTransform
from thermodepth.frames import FfcState
from thermodepth.radiometry import (
    ObjectParams,
    RadiometryParams,
    counts_from_kelvin,
    kelvin_from_counts,
    raw_to_celsius,
)
from thermodepth.sim import (
    DepthCameraModel,
    LeptonModel,
    Rig,
    Scene,
    camera_pose,
    constant_fpa,
    default_calibration,
    occlusion_scene,
    plate_scene,
    steps_fpa,
    wall_scene,
)
from thermodepth.sim.d435 import depth_sigma_m, ir_image
from thermodepth.sim.lepton import (
    LeptonSensor,
    counts_from_radiance,
    measured_radiance,
    radiance_table,
)
from thermodepth.sim.protocols import (
    SweepConfig,
    plate_roi,
    simulate_sweep,
    simulate_targets,
    write_frames,
)
from thermodepth.sweep import read_sweep_csv, write_sweep_csv

K0 = 273.15
T_REF = LeptonModel().vox_reference_temp_k


def flat_scene(temp_k: float, z_m: float) -> Scene:
    """A blackbody wall filling the view, in surroundings at its own temperature."""
    return wall_scene(z_m, temp_k - K0, emissivity=1.0, ambient_temp_c=temp_k - K0)


IDENTITY = RigidTransform.identity("world", "depth")


def test_noise_free_blackbody_counts_invert_to_true_temperature() -> None:
    # a blackbody filling the view at distance 0 (no air), FPA at the reference temperature
    table = radiance_table()
    model = LeptonModel()
    for temp_c in (-10.0, 25.0, 39.0, 70.0, 150.0):
        aperture = np.full((120, 160), table.to_radiance(temp_c + K0))
        sensor = LeptonSensor(
            model, (120, 160), constant_fpa(T_REF), np.random.default_rng(0), noise=False
        )
        counts, _ = sensor.read(1.0, aperture)
        t = kelvin_from_counts(counts, model.planck) - K0
        assert np.max(np.abs(t - temp_c)) < 1e-3


def test_counts_follow_paper_constants() -> None:
    table = radiance_table()
    s = counts_from_radiance(table.to_radiance(39 + K0), LeptonModel(), table)
    assert s == pytest.approx(counts_from_kelvin(39 + K0, LeptonModel().planck), abs=1e-3)
    assert s == pytest.approx(8502, abs=1)


def test_netd_of_flat_scene() -> None:
    rig = Rig(flat_scene(300.0, 2.0), IDENTITY, fpa=constant_fpa(T_REF), seed=3, start_s=1.0)
    frames = np.stack([f.thermal.astype(float) for f in rig.frames(60)])
    per_pixel_sd = frames.std(axis=0, ddof=1).mean()
    model = LeptonModel()
    ds_dt = np.diff(counts_from_kelvin([299.95, 300.05], model.planck))[0] / 0.1
    netd = per_pixel_sd / ds_dt
    assert netd == pytest.approx(model.netd_k, rel=0.10)


@pytest.mark.parametrize("z_m", [0.6, 1.5, 3.0, 6.0])
def test_depth_noise_follows_z_squared_model(z_m: float) -> None:
    rig = Rig(flat_scene(298.15, z_m), IDENTITY, seed=int(z_m * 10))
    frame = rig.frame()
    cal = rig.calibration
    valid = frame.depth > 0
    err = frame.depth[valid] * cal.depth_scale_m - z_m
    expected = depth_sigma_m(z_m, cal.depth.fx, DepthCameraModel())
    quantisation = cal.depth_scale_m / np.sqrt(12)
    assert err.std() == pytest.approx(np.hypot(expected, quantisation), rel=0.05)
    assert abs(err.mean()) < 0.1 * expected + 1e-4


def test_depth_range_limits() -> None:
    near = Rig(flat_scene(298.15, 0.15), IDENTITY).frame()
    far = Rig(flat_scene(298.15, 12.0), IDENTITY).frame()
    assert not near.depth.any() and not far.depth.any()


def test_stereo_shadow_left_of_near_object() -> None:
    rig = Rig(
        occlusion_scene(box_distance_m=0.8, wall_distance_m=2.0),
        RigidTransform.identity("world", "depth"),
    )
    depth = rig.frame().depth
    row = depth[360]
    box_cols = np.flatnonzero((row > 0) & (row < 1200))
    left_edge = box_cols.min()
    # band width = fx B (1/z_near - 1/z_far), 50 mm baseline
    band = 645.0 * 0.050 * (1 / 0.8 - 1 / 2.0)
    zeros = np.flatnonzero(row[:left_edge] == 0)
    assert zeros.size == pytest.approx(band, abs=2)
    assert zeros.min() >= left_edge - band - 2  # right next to the edge, on its left
    assert not np.any(row[box_cols.max() + 1 : box_cols.max() + 30] == 0)  # none on the right


def _plate_reading(
    plate_c: float, distance_m: float, fpa_k: float = T_REF, emissivity: float = 0.95
) -> float:
    """Noise-free ROI reading with emissivity but without distance correction."""
    rig = Rig(plate_scene(plate_temp_c=plate_c), camera_pose(distance_m))
    model, table = rig.lepton, radiance_table()
    roi = rig.aperture[plate_roi(rig, 2)]
    counts = counts_from_radiance(measured_radiance(roi, fpa_k, model, table), model, table)
    params = RadiometryParams(
        obj=ObjectParams(
            emissivity=emissivity, distance_m=0.0, reflected_temp_k=298.15, atmosphere_temp_k=298.15
        )
    )
    return float(np.mean(raw_to_celsius(counts, params)))


def test_hot_target_reads_lower_as_distance_grows() -> None:
    readings = [_plate_reading(60.0, d) for d in (0.5, 1.0, 2.0, 3.0, 4.0)]
    assert np.all(np.diff(readings) < 0)
    assert readings[0] - readings[-1] > 0.2


def test_sim_agrees_with_flir_radiometry_when_distance_is_known() -> None:
    # The sim mixes radiance; the FLIR model mixes counts. They agree closely (2 mK at 39 C).
    rig = Rig(plate_scene(), camera_pose(1.5))
    model, table = rig.lepton, radiance_table()
    sl = plate_roi(rig, 1)
    counts = counts_from_radiance(
        measured_radiance(rig.aperture[sl], T_REF, model, table), model, table
    )
    rng_m = rig.truth().thermal_range_m[sl]
    params = RadiometryParams(obj=ObjectParams(0.95, rng_m, 298.15, 298.15, 0.5))
    assert np.abs(raw_to_celsius(counts, params) - 39.0).max() < 0.005


def test_small_target_reads_cooler_as_it_recedes() -> None:
    peaks = []
    for d in (0.5, 1.5, 3.0):
        rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(d))
        params = RadiometryParams(obj=ObjectParams(0.95, d, 298.15, 298.15))
        counts = counts_from_radiance(
            measured_radiance(rig.aperture, T_REF, rig.lepton, radiance_table()),
            rig.lepton,
            radiance_table(),
        )
        peaks.append(float(np.nanmax(raw_to_celsius(counts, params))))
    assert peaks[0] > peaks[1] > peaks[2]
    assert peaks[0] > 65.0  # 2 cm chip at 0.5 m spans ~6 px: close to its true 70 C
    assert peaks[2] < 55.0  # at 3 m it spans ~1 px: the footprint and PSF average it down


def test_readings_rise_with_fpa_temperature_concave() -> None:
    fpa_c = np.array([25.0, 30.0, 35.0, 40.0])
    r = np.array([_plate_reading(39.0, 0.5, c + K0) for c in fpa_c])
    steps = np.diff(r)
    assert np.all(steps > 0)  # rises with the VOx temperature (paper Fig. 13)
    assert np.all(np.diff(steps) < 0)  # concave, logarithmic-looking
    assert 2.0 < r[-1] - r[0] < 3.0  # +2 to +3 C over 25 -> 40 C
    # the paper's own ln fit at 0.5 m gives 37.15 C at 25 C and 39.78 C at 40 C
    assert r[0] == pytest.approx(5.595 * np.log(25) + 19.14, abs=0.3)
    assert r[-1] == pytest.approx(5.595 * np.log(40) + 19.14, abs=0.3)


def test_determinism_for_a_seed() -> None:
    a = [f for f in Rig(plate_scene(chip_temp_c=70), camera_pose(1.0), seed=7).frames(3)]
    b = [f for f in Rig(plate_scene(chip_temp_c=70), camera_pose(1.0), seed=7).frames(3)]
    c = Rig(plate_scene(chip_temp_c=70), camera_pose(1.0), seed=8).frame()
    for fa, fb in zip(a, b, strict=True):
        np.testing.assert_array_equal(fa.depth, fb.depth)
        np.testing.assert_array_equal(fa.thermal, fb.thermal)
        assert fa.telemetry == fb.telemetry
    assert not np.array_equal(a[0].depth, c.depth)


def test_timestamps_and_telemetry() -> None:
    rig = Rig(plate_scene(), camera_pose(1.0), start_s=1.0)
    frames = list(rig.frames(30))
    t = np.array([f.thermal_time_s for f in frames])
    np.testing.assert_allclose(np.diff(t), 1 / 8.7)
    assert max(abs(f.skew_s) for f in frames) <= 1 / 60 + 1e-12
    np.testing.assert_allclose(
        np.array([f.depth_time_s for f in frames]) * 30 % 1, 0.004 * 30 % 1, atol=1e-9
    )
    assert [f.telemetry.frame_counter for f in frames] == list(range(30))
    assert all(f.telemetry.fpa_temp_k == pytest.approx(308.15) for f in frames)
    assert frames[0].telemetry.housing_temp_k == pytest.approx(307.15)


def test_ffc_cycle_flags_frames_and_resets_fixed_pattern() -> None:
    # FPA steps by 2 K at t = 5 s: more than ffc_delta_k, so an FFC follows
    fpa = steps_fpa([0.0, 5.0], [305.0, 307.0])
    rig = Rig(flat_scene(300.0, 2.0), IDENTITY, fpa=fpa, seed=1)
    frames = list(rig.frames(70))
    states = [f.telemetry.ffc_state for f in frames]
    assert states[0] == FfcState.IN_PROGRESS  # the power-on FFC
    in_ffc = [i for i, s in enumerate(states) if s == FfcState.IN_PROGRESS]
    step = int(np.ceil(5.0 * 8.7))
    assert step in in_ffc and all(i < 3 or i >= step for i in in_ffc)
    shutter = frames[step].thermal.astype(float)
    assert shutter.std() < 3 * LeptonModel().noise_counts  # uniform: the closed shutter
    # offsets drift after the step, then the FFC re-levels them
    after = [f for f in frames[step:] if f.telemetry.ffc_state == FfcState.COMPLETE]
    assert after and after[0].telemetry.time_since_ffc_s is not None
    assert after[0].telemetry.time_since_ffc_s < 0.2
    drift_before = np.std(frames[step - 1].thermal.astype(float) - frames[20].thermal)
    assert drift_before < 3.0  # same FPA, same offsets: only temporal noise


def test_ground_truth_correspondences_reproject_exactly() -> None:
    rig = Rig(occlusion_scene(), RigidTransform.identity("world", "depth"))
    truth = rig.truth()
    cal = rig.calibration
    vis = truth.visible_in_thermal
    assert vis.sum() > 100_000
    v, u = np.nonzero(vis)
    z = truth.depth_z_m[vis]
    pts_t = cal.thermal_from_depth.apply(cal.depth.deproject(np.stack([u, v], -1), z))
    np.testing.assert_allclose(
        cal.thermal.project(pts_t), truth.thermal_pixel_of_depth[vis], atol=1e-9
    )
    # what the thermal camera sees along that pixel is the same surface, at the same range
    back = cal.thermal.deproject(truth.thermal_pixel_of_depth[vis], pts_t[:, 2])
    np.testing.assert_allclose(back, pts_t, atol=1e-9)


def test_occluded_pixels_are_wall_right_of_the_box() -> None:
    scene = occlusion_scene(box_distance_m=0.8, wall_distance_m=2.0)
    rig = Rig(scene, RigidTransform.identity("world", "depth"))
    truth = rig.truth()
    occ = truth.occluded_in_thermal
    box_ids = [i for i, r in enumerate(scene.rects) if r.name.startswith("box")]
    assert occ.sum() > 1000
    assert not np.isin(truth.depth_rect[occ], box_ids).any()  # the box itself is never hidden
    box_cols = np.flatnonzero(np.isin(truth.depth_rect[360], box_ids))
    box_rows = np.flatnonzero(np.isin(truth.depth_rect[:, 640], box_ids))
    # on the box's middle row the hidden band lies right of it: the thermal camera sits 40 mm
    # to the left; its width ~ fx_d * baseline_x * (1/z_box - 1/z_wall)
    row = np.flatnonzero(occ[360])
    assert row.min() > box_cols.max()
    expected = 645.0 * 0.040 * (1 / 0.8 - 1 / 2.0)
    assert row.size == pytest.approx(expected, rel=0.15)
    # 6 mm of vertical offset hides a thin band (~3 px) along a horizontal edge
    v = np.nonzero(occ)[0]
    assert v.min() >= box_rows.min() - 6 and v.max() <= box_rows.max() + 6
    assert not (occ & truth.visible_in_thermal).any()


def test_truth_temperatures() -> None:
    rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(1.0))
    truth = rig.truth()
    temps = set(np.unique(np.round(truth.depth_temp_k - K0, 6)))
    assert {25.0, 39.0, 70.0} <= temps
    assert np.nanmax(truth.thermal_temp_k) == pytest.approx(70 + K0)


def test_calibration_is_valid_and_non_trivial(tmp_path: Path) -> None:
    cal = default_calibration()
    cal.save(tmp_path / "c.yaml")
    back = Calibration.load(tmp_path / "c.yaml")
    assert 0.03 <= back.baseline_m <= 0.05
    # parallax at 0.5 m is several thermal pixels
    assert cal.thermal.fx * cal.baseline_m / 0.5 > 8
    assert cal.thermal.hfov_deg == pytest.approx(56.0, abs=0.1)


def test_sweep_rows_and_csv_round_trip(tmp_path: Path) -> None:
    cfg = SweepConfig(distances_m=(0.5, 2.5), plate_temps_c=(39.0, 50.0), samples=200)
    table = simulate_sweep(cfg)
    assert set(np.unique(table["distance_m"])) == {0.5, 2.5}
    assert set(np.unique(table["reference_temp_c"])) == {39.0, 50.0}
    assert table["vox_temp_c"].min() >= 25.0 and table["vox_temp_c"].max() <= 40.0
    # FFC frames are left out: a 15 K ramp with an FFC every 1.5 K is ~10 FFCs of 2-3 frames
    excluded = 4 * 200 - len(table)
    assert 4 * 10 * 2 <= excluded <= 4 * 11 * 3
    path = tmp_path / "sweep.csv"
    write_sweep_csv(path, table)
    back = read_sweep_csv(path)
    np.testing.assert_allclose(back["measured_temp_c"], table["measured_temp_c"], atol=1e-4)
    hot = table["reference_temp_c"] == 50.0
    assert abs(np.mean(table["measured_temp_c"][hot]) - 50.0) < 1.5


def test_target_captures(tmp_path: Path) -> None:
    import cv2

    caps = simulate_targets(
        tmp_path, BoardSpec.parse("checkerboard:9x6", 0.03), n_poses=2, thermal_supersample=4
    )
    assert len(caps.pairs) == 2
    ir = cv2.imread(str(caps.pairs[0][0]), cv2.IMREAD_UNCHANGED)
    th = cv2.imread(str(caps.pairs[0][1]), cv2.IMREAD_UNCHANGED)
    assert ir.shape == (720, 1280) and ir.dtype == np.uint8
    assert th.shape == (120, 160) and th.dtype == np.uint16
    found, _ = cv2.findChessboardCornersSB(ir, (9, 6))
    assert found
    assert np.ptp(th) > 300  # the heated board stands out: paint vs bare metal


def test_written_frames_carry_their_truth(tmp_path: Path) -> None:
    paths = write_frames(tmp_path, plate_scene(chip_temp_c=70.0), 1.0, 2, seed=4)
    assert [p.name for p in paths] == ["frame_000000.npz", "frame_000001.npz"]
    cal = Calibration.load(tmp_path / "calibration.yaml")
    rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(1.0), seed=4, start_s=1.0)
    truth = rig.truth()
    for path, pair in zip(paths, rig.frames(2), strict=True):
        with np.load(path) as z:
            np.testing.assert_array_equal(z["depth"], pair.depth)
            np.testing.assert_array_equal(z["thermal"], pair.thermal)
            assert z["thermal_time_s"] == pair.thermal_time_s
            np.testing.assert_array_equal(
                z["thermal_range_m"], truth.thermal_range_m.astype(np.float32)
            )
            assert z["visible_in_thermal"].sum() == truth.visible_in_thermal.sum() > 0
    assert cal.thermal == rig.calibration.thermal


@pytest.mark.parametrize(
    "model", [DepthCameraModel(), DepthCameraModel(noise=False), DepthCameraModel(ir_noise_dn=80.0)]
)
def test_the_ir_image_rounds_and_clips_its_albedo_as_numpy_does(model: DepthCameraModel) -> None:
    # rint(albedo gain + noise sigma) clipped to 0..255, bit for bit numpy's array expression:
    # halves round to even, out-of-range values clip
    albedo = np.random.default_rng(1).uniform(-0.2, 1.3, (72, 128))
    albedo[0, :40] = (np.arange(40) + 0.5) / model.ir_gain  # exact halves
    expected = albedo * model.ir_gain
    rng = np.random.default_rng(5)
    if model.noise:
        expected = expected + rng.standard_normal(albedo.shape) * model.ir_noise_dn
    expected = np.clip(np.rint(expected), 0, 255).astype(np.uint8)
    got = ir_image(albedo, model, np.random.default_rng(5))
    np.testing.assert_array_equal(got, expected)
    assert got.min() == 0 and got.max() == 255
