"""Depth <-> thermal registration against the simulated rig's exact ground truth."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from peers import near_pixel_border, nearest_index
from thermodepth.calibration import Calibration
from thermodepth.camera import Intrinsics, RigidTransform, rotation_from_euler
from thermodepth.evaluation import registration_error
from thermodepth.registration import Reason, Registration
from thermodepth.registration.reproject import depth_pixel_spacing
from thermodepth.sim import (
    DepthCameraModel,
    Rig,
    default_calibration,
    occlusion_scene,
    wall_scene,
)
from thermodepth.sim.d435 import depth_sigma_m

IDENTITY = RigidTransform.identity("world", "depth")
CAL = default_calibration()
H, W = CAL.depth.shape
h, w = CAL.thermal.shape
INDEX = np.arange(h * w, dtype=np.float32).reshape(h, w)


def _near_border(px: np.ndarray, eps: float) -> np.ndarray:
    """True where a thermal position (..., 2) lies within ``eps`` px of a pixel border."""
    return near_pixel_border(px[..., 0], px[..., 1], eps)


def _nearest(px: np.ndarray) -> np.ndarray:
    """Flat index of the thermal pixel nearest to each position (..., 2); -1 where NaN."""
    return nearest_index(CAL, px[..., 0], px[..., 1])[0]


def _shift_px(z_m: float) -> float:
    """RMS thermal-position shift that depth noise causes: fx_t |t| sigma_z / z^2."""
    sigma = depth_sigma_m(z_m, CAL.depth.fx, DepthCameraModel())
    return CAL.thermal.fx * CAL.baseline_m * sigma / z_m**2


@pytest.mark.parametrize(("box_m", "wall_m"), [(0.5, 1.2), (1.0, 2.0), (1.8, 3.0)])
def test_nearest_thermal_pixel_is_right_and_occlusion_flagged(box_m: float, wall_m: float) -> None:
    rig = Rig(occlusion_scene(box_distance_m=box_m, wall_distance_m=wall_m), IDENTITY, seed=2)
    frame, truth = rig.frame(), rig.truth()
    got, reason = Registration(rig.calibration).thermal_to_depth(frame.depth, INDEX)
    valid = frame.depth > 0
    visible = truth.visible_in_thermal & valid
    right = (reason == Reason.OK) & (got == _nearest(truth.thermal_pixel_of_depth))
    # The depth noise shifts a point ~0.015 px at any distance (sigma_z ~ z^2, parallax ~
    # 1/z^2): a point that close to a pixel border is a tie no method can call. 0.05 px is
    # over 3 sigma of that shift.
    assert _shift_px(box_m) < 0.02 and _shift_px(wall_m) < 0.02
    ties = _near_border(truth.thermal_pixel_of_depth, 0.05)
    assert right[visible & ~ties].mean() >= 0.995
    assert right[visible].mean() >= 0.98  # ties included
    occluded = truth.occluded_in_thermal & valid
    assert occluded.sum() > 500
    assert (reason[occluded] == Reason.OCCLUDED).mean() >= 0.99
    # visible surfaces are almost never called hidden: only mixed pixels at the box's edge
    assert (reason[visible] == Reason.OCCLUDED).mean() < 0.005


@pytest.mark.parametrize(
    ("thermal", "depth", "spacing", "radius"),
    [
        ("lepton3", "1280x720", (0.22, 0.25), 0),
        ("p2pro", "848x480", (0.55, 0.62), 0),
        ("boson640", "1280x720", (1.04, 1.12), 1),
        ("boson640", "848x480", (1.55, 1.7), 1),
    ],
)
def test_finer_thermal_pixels_leave_no_hole_for_a_hidden_surface(
    thermal: str, depth: str, spacing: tuple[float, float], radius: int
) -> None:
    # A Boson 640 beside a D435 at 848x480: neighbouring depth pixels land 1.6 thermal px
    # apart, so a plain z-buffer leaves 61 % of the thermal pixels empty and the wall hidden
    # behind a box at 0.7 m took the box's temperature through them (1608 of 2554 pixels,
    # measured before the dilation). Each thermal pixel now takes the nearest surface within
    # the spacing: none bleeds, and visible surfaces are not called hidden.
    scene = occlusion_scene(box_distance_m=0.7, wall_distance_m=1.8)
    rig = Rig.of_cameras(scene, IDENTITY, thermal, depth, seed=2)
    reg = Registration(rig.calibration)
    lo, hi = spacing
    assert lo < depth_pixel_spacing(rig.calibration) < hi
    assert reg.strategy.dilation == radius
    frame, truth = rig.frame(), rig.truth()
    th, tw = rig.calibration.thermal.shape
    index = np.arange(th * tw, dtype=np.float32).reshape(th, tw)
    got, reason = reg.thermal_to_depth(frame.depth, index)
    box = np.array([r.name.startswith("box") for r in scene.rects])
    thermal_sees_box = box[truth.thermal_rect].ravel()
    valid = frame.depth > 0
    wall = ~box[np.maximum(truth.depth_rect, 0)] & (truth.depth_rect >= 0) & valid
    ok = wall & (reason == Reason.OK)
    assert (truth.occluded_in_thermal & wall).sum() > 2000
    assert thermal_sees_box[got[ok].astype(int)].sum() == 0
    assert (reason[truth.occluded_in_thermal & valid] == Reason.OCCLUDED).mean() >= 0.98
    assert (reason[truth.visible_in_thermal & valid] == Reason.OCCLUDED).mean() < 0.005
    # the distance map has no holes inside surfaces either: only where no surface is seen
    z_m = reg.depth_to_thermal(frame.depth).z_m
    assert np.isnan(z_m).mean() < 0.05


@pytest.mark.parametrize("distance_m", [0.5, 1.0, 2.0, 3.0])
def test_noise_free_depth_gives_the_true_pixel(distance_m: float) -> None:
    err = registration_error(distance_m, "reproject", depth_noise=False)
    assert err.nearest_right >= 0.995
    assert err.p95_px < 0.005  # only the 1 mm depth quantum is left


def test_hot_occluder_does_not_bleed_onto_the_wall() -> None:
    scene = occlusion_scene(box_distance_m=0.8, wall_distance_m=2.0)
    rig = Rig(scene, IDENTITY)
    frame, truth = rig.frame(), rig.truth()
    got, reason = Registration(rig.calibration).thermal_to_depth(frame.depth, INDEX)
    box = np.array([r.name.startswith("box") for r in scene.rects])
    thermal_sees_box = box[truth.thermal_rect].ravel()  # what each thermal pixel centre sees
    wall = ~box[np.maximum(truth.depth_rect, 0)] & (truth.depth_rect >= 0) & (frame.depth > 0)
    ok = wall & (reason == Reason.OK)
    bled = thermal_sees_box[got[ok].astype(int)]
    # without the z-buffer test (librealsense's align) the hidden band of wall, ~19 x 200
    # depth pixels, would take the box's temperature; with it only edge pixels can
    assert (truth.occluded_in_thermal & wall).sum() > 3000
    assert bled.sum() < 0.1 * (truth.occluded_in_thermal & wall).sum()


def test_depth_to_thermal_matches_truth() -> None:
    rig = Rig(wall_scene(2.0), IDENTITY, seed=4)
    frame, truth = rig.frame(), rig.truth()
    z, rng = Registration(rig.calibration).depth_to_thermal(frame.depth)
    assert z.dtype == np.float32 and z.shape == (h, w)
    sigma = depth_sigma_m(2.0, CAL.depth.fx, DepthCameraModel())
    both = np.isfinite(z) & np.isfinite(truth.thermal_z_m)
    assert both.mean() > 0.99
    # the z-buffer keeps the nearest of ~20 noisy samples per pixel: ~1-2 sigma in front
    bias = np.median(z[both] - truth.thermal_z_m[both])
    assert -3 * sigma < bias < 0
    # range / Z is the ray's length; the nearest point lies anywhere in its pixel, not on the
    # centre ray the truth uses: half a pixel changes it by up to ~0.3 % at the corners
    np.testing.assert_allclose(
        rng[both] / z[both], truth.thermal_range_m[both] / truth.thermal_z_m[both], rtol=5e-3
    )


def test_bilinear_follows_a_smooth_image() -> None:
    rig = Rig(wall_scene(1.5), IDENTITY, depth_model=DepthCameraModel(noise=False))
    frame, truth = rig.frame(), rig.truth()
    reg = Registration(rig.calibration)
    ramp = np.tile(np.arange(w, dtype=np.float32), (h, 1))  # value = column
    near, _ = reg.thermal_to_depth(frame.depth, ramp)
    lin, reason = reg.thermal_to_depth(frame.depth, ramp, interpolation="bilinear")
    u_true = truth.thermal_pixel_of_depth[..., 0]
    inner = (reason == Reason.OK) & (u_true > 1) & (u_true < w - 2)
    assert np.abs(lin[inner] - u_true[inner]).max() < 0.01
    # nearest: the true column, except within the 1 mm depth quantum's reach of a border
    clear = inner & ~_near_border(truth.thermal_pixel_of_depth, 0.005)
    assert np.array_equal(near[clear], np.floor(u_true[clear] + 0.5))


def test_reuses_the_zbuffer_of_depth_to_thermal() -> None:
    rig = Rig(occlusion_scene(), IDENTITY)
    frame = rig.frame()
    reg = Registration(rig.calibration)
    a = reg.thermal_to_depth(frame.depth, frame.thermal)
    b = reg.thermal_to_depth(frame.depth, frame.thermal, nearest=reg.depth_to_thermal(frame.depth))
    np.testing.assert_array_equal(a.values, b.values)
    np.testing.assert_array_equal(a.reason, b.reason)


@pytest.mark.parametrize("n_chunks", [1, 2, 5])
@pytest.mark.parametrize("scene", ["random", "random, some at 5 cm", "box before a wall"])
def test_each_row_chunk_builds_all_the_zbuffer_it_samples(n_chunks: int, scene: str) -> None:
    # Standalone, each chunk of rows builds the z-buffer of the thermal pixels it samples: it
    # projects the rows around its own that can land there, and samples a row once no row
    # still to project can. Random depths hide most points behind a nearer neighbour, in every
    # thermal pixel and across every chunk border, and give each row a wide depth range: one
    # row too few and a hidden point would pass as seen. The box before a wall gives each row
    # a narrow depth range, so rows are sampled soon after they are projected, and its edges
    # cross chunk borders. The thermal camera, rolled 6 deg and shifted 3 cm up, puts each
    # depth row across many thermal rows. Depths of 5 cm are nearer than the view table
    # reaches: the whole z-buffer is then built first. Each time the result is exactly that
    # with the z-buffer of depth_to_thermal.
    transform = RigidTransform(
        rotation_from_euler(0.1, 0.02, -0.03), np.array([0.04, -0.03, 0.004]), "thermal", "depth"
    )
    cal = Calibration(CAL.depth, CAL.thermal, CAL.depth_scale_m, transform)
    reg = Registration(cal)
    reg._n_chunks = n_chunks  # more chunk borders than this machine has threads
    if scene == "box before a wall":
        depth = Rig(occlusion_scene(), IDENTITY).frame().depth
    else:
        depth = np.random.default_rng(3).integers(300, 6000, (H, W), dtype=np.uint16)
        if scene.endswith("5 cm"):
            depth[::97, ::89] = 50
    thermal = np.random.default_rng(4).normal(30.0, 5.0, (h, w)).astype(np.float32)
    nearest = reg.depth_to_thermal(depth)
    for interpolation in ("nearest", "bilinear"):
        index = np.empty((H, W), np.int32)
        alone = reg.thermal_to_depth(depth, thermal, interpolation, thermal_index=index)
        given_index = np.empty((H, W), np.int32)
        given = reg.thermal_to_depth(
            depth, thermal, interpolation, nearest=nearest, thermal_index=given_index
        )
        assert (alone.reason == Reason.OCCLUDED).sum() > 1000
        assert (alone.reason == Reason.OK).sum() > 10_000
        np.testing.assert_array_equal(alone.reason, given.reason)
        np.testing.assert_array_equal(alone.values, given.values)
        np.testing.assert_array_equal(index, given_index)


def test_more_row_chunks_than_rows() -> None:
    # a depth image of 3 rows on 5 chunks: two of them get no row
    narrow = Intrinsics(203, 3, 320.0, 320.0, 101.0, 1.0)
    cal = Calibration(narrow, CAL.thermal, CAL.depth_scale_m, CAL.thermal_from_depth)
    reg = Registration(cal, chunks=5)
    depth = np.full(narrow.shape, 1500, np.uint16)
    values, reason = reg.thermal_to_depth(depth, INDEX)
    np.testing.assert_array_equal(reason, Reason.OK)
    given = reg.thermal_to_depth(depth, INDEX, nearest=reg.depth_to_thermal(depth))
    np.testing.assert_array_equal(values, given.values)


def test_distortion_guard_refuses_folded_points() -> None:
    # Strong barrel: r (1 + k1 r^2) peaks at r^2 = 1 / (3 * 0.45); the wide depth view
    # reaches far beyond, where the polynomial would fold points back into the image.
    thermal = replace(CAL.thermal, distortion=np.array([-0.45, 0, 0, 0, 0.0]))
    cal = Calibration(CAL.depth, thermal, CAL.depth_scale_m, CAL.thermal_from_depth)
    depth = np.full((H, W), 1500, dtype=np.uint16)
    _, reason = Registration(cal).thermal_to_depth(depth, INDEX)
    u, v = CAL.depth.pixel_grid()
    pts = cal.thermal_from_depth.apply(CAL.depth.deproject(np.stack([u, v], -1), 1.5))
    x, y = pts[..., 0] / pts[..., 2], pts[..., 1] / pts[..., 2]
    r2 = x * x + y * y
    folded = (1 - 0.45 * r2) * np.sqrt(r2) * thermal.fx  # naive radius in pixels
    beyond = r2 > 1 / (3 * 0.45)
    lands_inside = (
        beyond & (np.abs(folded * x / np.sqrt(r2)) < 80) & (np.abs(folded * y / np.sqrt(r2)) < 60)
    )
    assert lands_inside.sum() > 10_000  # without the guard these would pollute the image
    assert np.all(reason[beyond] == Reason.OUTSIDE)


def test_depth_camera_with_distortion_uses_full_ray_grid() -> None:
    depth_intr = replace(CAL.depth, distortion=np.array([0.05, -0.01, 0.0, 0.0, 0.0]))
    cal = Calibration(depth_intr, CAL.thermal, CAL.depth_scale_m, CAL.thermal_from_depth)
    depth = np.full((H, W), 2000, dtype=np.uint16)
    got, reason = Registration(cal).thermal_to_depth(depth, INDEX)
    u, v = depth_intr.pixel_grid()
    px = cal.thermal.project(
        cal.thermal_from_depth.apply(depth_intr.deproject(np.stack([u, v], -1), 2.0))
    )
    ok = reason == Reason.OK
    clear = ok & ~_near_border(px, 1e-3)
    expected = _nearest(px)
    assert ok.sum() > 300_000
    assert (got[clear] == expected[clear]).mean() > 0.9999


def test_paper_method_has_parallax_error_away_from_its_reference() -> None:
    near = registration_error(0.5, "paper")
    ref = registration_error(1.5, "paper")
    expected = CAL.thermal.fx * CAL.baseline_m * (1 / 0.5 - 1 / 1.5)  # 8 px
    assert near.median_px == pytest.approx(expected, rel=0.1)
    assert ref.median_px < 1.0
    assert registration_error(0.5, "reproject").median_px < 0.05


def test_paper_method_both_directions() -> None:
    rig = Rig(wall_scene(1.5), IDENTITY)
    frame = rig.frame()
    reg = Registration(rig.calibration, method="paper")
    z, rng = reg.depth_to_thermal(frame.depth)
    assert np.nanmedian(z) == pytest.approx(1.5, abs=0.01)
    assert np.all(rng[np.isfinite(z)] >= z[np.isfinite(z)])
    values, reason = reg.thermal_to_depth(frame.depth, frame.thermal)
    assert set(np.unique(reason)) <= {Reason.OK, Reason.OUTSIDE}
    assert np.isnan(values[reason != Reason.OK]).all()


@pytest.mark.parametrize("method", ["reproject", "paper"])
@pytest.mark.parametrize("interpolation", ["nearest", "bilinear"])
def test_thermal_index_is_the_pixel_each_depth_pixel_sees(method: str, interpolation: str) -> None:
    rig = Rig(occlusion_scene(), IDENTITY)
    frame = rig.frame()
    reg = Registration(rig.calibration, method=method)
    index = np.full((H, W), 7, np.int32)
    values, reason = reg.thermal_to_depth(
        frame.depth, frame.thermal, interpolation, thermal_index=index
    )
    picked, _ = reg.thermal_to_depth(frame.depth, INDEX)  # the pixel index as the image
    ok = reason == Reason.OK
    assert ok.mean() > 0.3 and (reason == Reason.OCCLUDED).any() == (method == "reproject")
    np.testing.assert_array_equal(index[ok], picked[ok].astype(np.int32))
    assert np.all(index[~ok] == -1)
    if interpolation == "nearest":  # the values are those of the indexed pixels
        np.testing.assert_array_equal(values[ok], frame.thermal.ravel()[index[ok]])
    with pytest.raises(ValueError, match="thermal_index must be a C-contiguous int32"):
        reg.thermal_to_depth(frame.depth, INDEX, thermal_index=np.empty((H, W), np.int64))


@pytest.mark.parametrize("method", ["reproject", "paper"])
def test_all_zero_depth_gives_all_nan_without_warnings(method: str) -> None:
    # pytest turns RuntimeWarning into an error (pyproject), so none may escape
    reg = Registration(CAL, method=method)
    depth = np.zeros((H, W), np.uint16)
    z, rng = reg.depth_to_thermal(depth)
    assert np.isnan(z).all() and np.isnan(rng).all()
    values, reason = reg.thermal_to_depth(depth, np.full((h, w), 8000, np.uint16))
    assert np.isnan(values).all()
    assert np.all(reason == Reason.INVALID_DEPTH)


@pytest.mark.parametrize(
    ("depth", "thermal", "message"),
    [
        (
            np.zeros((H, W), np.float32),
            np.zeros((h, w)),
            r"depth must be a uint16 array of shape \(720, 1280\)",
        ),
        (np.zeros((W, H), np.uint16), np.zeros((h, w)), r"got uint16 \(1280, 720\)"),
        (
            np.zeros((H, W), np.uint16),
            np.zeros((w, h)),
            r"thermal must be a numeric array of shape \(120, 160\)",
        ),
        (np.zeros((H, W), np.uint16), np.zeros((h, w), dtype=bool), "thermal must be a numeric"),
    ],
)
def test_bad_shapes_and_dtypes(depth: np.ndarray, thermal: np.ndarray, message: str) -> None:
    reg = Registration(CAL)
    with pytest.raises(ValueError, match=message):
        reg.thermal_to_depth(depth, thermal)


def test_unknown_method_and_interpolation() -> None:
    with pytest.raises(ValueError, match="unknown registration method"):
        Registration(CAL, method="magic")
    with pytest.raises(ValueError, match="interpolation"):
        Registration(CAL).thermal_to_depth(np.zeros((H, W), np.uint16), INDEX, "cubic")


def test_from_file(tmp_path: Path) -> None:
    CAL.save(tmp_path / "cal.yaml")
    reg = Registration.from_file(tmp_path / "cal.yaml", method="paper")
    assert reg.method == "paper" and reg.calibration.thermal == CAL.thermal
