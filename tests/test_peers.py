"""Registration peers (tests/peers.py).

The float64 numpy reference holds the numba kernels of thermodepth.registration to account;
librealsense's rs.align and OpenCV's registerDepth agree with them in the ways documented in
tests/peers.py (measured here on the simulated rig: a hot box 0.8 m in front of a wall).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pytest
from numpy.typing import NDArray

from peers import (
    RsAlign,
    border_exclusions,
    depth_frame_z,
    depth_to_thermal_agreement,
    import_pyrealsense2,
    nearest_index,
    numpy_reference,
    reference_depth_to_thermal,
    reference_thermal_to_depth,
    register_depth_cv2,
    registration_tolerance,
    rs_extrinsics,
    thermal_index_image,
    thermal_to_depth_agreement,
    without_thermal_distortion,
)
from thermodepth.calibration import Calibration
from thermodepth.camera import Intrinsics, RigidTransform, rotation_from_euler
from thermodepth.registration import Reason, Registration
from thermodepth.sim import Rig, default_calibration, occlusion_scene

F64 = NDArray[np.float64]
IDENTITY = RigidTransform.identity("world", "depth")


@pytest.fixture(scope="module")
def depth() -> NDArray[np.uint16]:
    return Rig(occlusion_scene(), IDENTITY).frame().depth


@dataclass
class Case:
    cal: Calibration
    registration: Registration
    projected: tuple[F64, F64, F64]
    zbuffer: F64
    tie: NDArray[np.bool_]
    tie_thermal: NDArray[np.bool_]


@pytest.fixture(scope="module", params=["k1-k2-distortion", "no-distortion"])
def case(request: pytest.FixtureRequest, depth: NDArray[np.uint16]) -> Case:
    cal = default_calibration()
    if request.param == "no-distortion":
        cal = without_thermal_distortion(cal)
    else:
        assert cal.thermal.has_distortion  # k1 = -0.08, k2 = 0.02, small p1, p2
    projected = numpy_reference(cal, depth)
    tie, tie_thermal = border_exclusions(cal, projected, eps_px=1e-3)
    zbuf = reference_depth_to_thermal(cal, depth, projected)
    return Case(cal, Registration(cal), projected, zbuf, tie, tie_thermal)


# ---------------------------------------------------------------------------------------------
# numpy reference vs the numba kernels
# ---------------------------------------------------------------------------------------------


def test_reference_depth_to_thermal_matches_kernels(case: Case, depth: NDArray[np.uint16]) -> None:
    # Same z-buffer on >= 99.9 % of the thermal pixels (Z within float32 rounding, 1e-5),
    # leaving out those a depth pixel within 1e-3 px of a pixel border may land in.
    ours = case.registration.depth_to_thermal(depth)
    assert 0.5 < np.isfinite(case.zbuffer).mean() < 1.0  # the depth covers most of the image
    assert case.tie_thermal.mean() < 0.2
    assert depth_to_thermal_agreement(ours.z_m, case.zbuffer, case.tie_thermal) >= 0.999


def test_depth_to_thermal_range_is_that_of_the_kept_point(
    case: Case, depth: NDArray[np.uint16]
) -> None:
    # The range beside each Z belongs to a depth point whose Z is the one kept: the float64
    # range lies within those of the points tied with the kept Z (float32 rounding, 1e-5).
    d = case.cal.depth
    u, v = d.pixel_grid()
    points = case.cal.thermal_from_depth.apply(
        d.deproject(np.stack([u, v], axis=-1), depth * case.cal.depth_scale_m)
    )
    range_m = np.linalg.norm(points, axis=-1)
    idx, ok = nearest_index(case.cal, case.projected[0], case.projected[1])
    kept_z = case.zbuffer.ravel()[np.where(ok, idx, 0)]
    tied = ok & (case.projected[2] <= kept_z * (1 + 1e-5))
    lo = np.full(case.zbuffer.size, np.inf)
    hi = np.full(case.zbuffer.size, -np.inf)
    np.minimum.at(lo, idx[tied], range_m[tied])
    np.maximum.at(hi, idx[tied], range_m[tied])
    ours = case.registration.depth_to_thermal(depth).range_m.ravel().astype(np.float64)
    keep = ~case.tie_thermal.ravel() & np.isfinite(case.zbuffer.ravel())
    assert keep.sum() > 10_000
    within = (ours >= lo * (1 - 1e-5)) & (ours <= hi * (1 + 1e-5))
    assert within[keep].mean() >= 0.999
    assert np.isnan(ours[np.isnan(case.zbuffer.ravel())]).all()


def test_reference_thermal_to_depth_matches_kernels(case: Case, depth: NDArray[np.uint16]) -> None:
    # Same reason and same thermal pixel on >= 99.9 % of the depth pixels, leaving out those
    # within 1e-3 px of a thermal pixel border; the box hides part of the wall from the
    # thermal camera, so the occlusion test is exercised.
    thermal = thermal_index_image(case.cal)
    values, reason = reference_thermal_to_depth(
        case.cal, depth, thermal, registration_tolerance(case.cal), case.projected, case.zbuffer
    )
    assert (reason == Reason.OCCLUDED).sum() > 300
    assert (reason == Reason.INVALID_DEPTH).sum() > 0
    assert case.tie.mean() < 0.01
    ours = case.registration.thermal_to_depth(depth, thermal)
    assert thermal_to_depth_agreement(ours.values, ours.reason, values, reason, case.tie) >= 0.999
    # given the z-buffer of the same frame, the kernel gives exactly what it does standalone
    given = case.registration.thermal_to_depth(
        depth, thermal, nearest=case.registration.depth_to_thermal(depth)
    )
    np.testing.assert_array_equal(given.reason, ours.reason)
    np.testing.assert_array_equal(given.values, ours.values)


def test_every_depth_pixel_counts_to_the_last_of_its_row() -> None:
    # A narrow depth camera of odd width (203 = 8 * 25 + 3: the strided scatter's classes end
    # unevenly) inside a wide thermal view: each row's span is the whole row, and every
    # pixel, the last ones included, must reach the z-buffer. Random depths, so the nearest
    # of the ~2 depth pixels per thermal pixel is anyone's.
    base = default_calibration()
    narrow = Intrinsics(203, 101, 320.0, 320.0, 101.0, 50.0)
    cal = Calibration(narrow, base.thermal, base.depth_scale_m, base.thermal_from_depth)
    depth = np.random.default_rng(7).integers(1500, 3000, narrow.shape, dtype=np.uint16)
    projected = numpy_reference(cal, depth)
    assert np.isfinite(projected[0]).all()  # every depth pixel lands in the thermal image
    tie, tie_thermal = border_exclusions(cal, projected, eps_px=1e-3)
    reg = Registration(cal)
    zbuf = reference_depth_to_thermal(cal, depth, projected)
    assert depth_to_thermal_agreement(reg.depth_to_thermal(depth).z_m, zbuf, tie_thermal) == 1.0
    thermal = thermal_index_image(cal)
    want = reference_thermal_to_depth(cal, depth, thermal, registration_tolerance(cal), projected)
    got = reg.thermal_to_depth(depth, thermal)
    assert thermal_to_depth_agreement(*got, *want, tie) == 1.0


def test_reference_occlusion_tolerance_is_passed_in(case: Case, depth: NDArray[np.uint16]) -> None:
    thermal = thermal_index_image(case.cal)
    args = (case.projected, case.zbuffer)
    _, strict = reference_thermal_to_depth(case.cal, depth, thermal, 0.0, *args)
    _, lenient = reference_thermal_to_depth(case.cal, depth, thermal, 10.0, *args)
    assert (lenient == Reason.OCCLUDED).sum() == 0
    assert (strict == Reason.OCCLUDED).sum() > (lenient == Reason.OCCLUDED).sum()


# ---------------------------------------------------------------------------------------------
# OpenCV registerDepth
# ---------------------------------------------------------------------------------------------


def test_register_depth_cv2_matches_kernels(case: Case, depth: NDArray[np.uint16]) -> None:
    # registerDepth also projects pixel centres, rounds to the nearest pixel and keeps the
    # nearest Z in the thermal frame: same z-buffer within float32 (its matrices are float32).
    try:
        z_cv = register_depth_cv2(case.cal, depth)
    except ImportError as exc:
        pytest.skip(str(exc))
    assert z_cv.shape == case.cal.thermal.shape and z_cv.dtype == np.float32
    ours = case.registration.depth_to_thermal(depth)
    assert depth_to_thermal_agreement(z_cv, ours.z_m, case.tie_thermal, rtol=1e-4) >= 0.999
    # the crop is an integer shift of the principal point: anywhere in the plane, the same
    # result but for a few pixel-border ties (float32 pixel coordinates near 380 instead of 80)
    moved = register_depth_cv2(case.cal, depth, origin=(300, 200))
    assert depth_to_thermal_agreement(moved, z_cv, rtol=0.0) >= 0.999


# ---------------------------------------------------------------------------------------------
# librealsense rs.align
# ---------------------------------------------------------------------------------------------


def rs_model_index(cal: Calibration, depth: NDArray[np.uint16], corner: float) -> NDArray[np.intp]:
    """librealsense's mapping, written out (float64): the depth pixel's corner (u + corner,
    v + corner) is deprojected, moved, distorted with modified_brown_conrady (tangential terms
    on the radially distorted coordinates) and rounded with int(x + 0.5), a truncation.
    Flat thermal index, -1 where none."""
    d, t = cal.depth, cal.thermal
    u, v = d.pixel_grid()
    z = depth * cal.depth_scale_m
    p = np.stack([(u + corner - d.cx) / d.fx * z, (v + corner - d.cy) / d.fy * z, z], axis=-1)
    q = cal.thermal_from_depth.apply(p)
    with np.errstate(divide="ignore", invalid="ignore"):
        x, y = q[..., 0] / q[..., 2], q[..., 1] / q[..., 2]
    k1, k2, p1, p2, k3 = t.distortion
    if t.has_distortion:
        r2 = x * x + y * y
        f = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xf, yf = x * f, y * f
        x = xf + 2 * p1 * xf * yf + p2 * (r2 + 2 * xf * xf)
        y = yf + 2 * p2 * xf * yf + p1 * (r2 + 2 * yf * yf)
    with np.errstate(invalid="ignore"):
        iu = np.trunc(t.fx * x + t.cx + 0.5)
        iv = np.trunc(t.fy * y + t.cy + 0.5)
        ok = (depth > 0) & (iu >= 0) & (iu < t.width) & (iv >= 0) & (iv < t.height)
    return np.where(ok, np.where(ok, iv, 0) * t.width + np.where(ok, iu, 0), -1).astype(np.intp)


def rs_model_thermal_to_depth(
    cal: Calibration, depth: NDArray[np.uint16], thermal: NDArray[np.uint16]
) -> NDArray[np.uint16]:
    idx = rs_model_index(cal, depth, +0.5)  # bottom-right corner
    return np.where(idx >= 0, thermal.ravel()[np.maximum(idx, 0)], 0).astype(np.uint16)


def rs_model_depth_to_thermal(cal: Calibration, depth: NDArray[np.uint16]) -> NDArray[np.uint16]:
    idx = rs_model_index(cal, depth, -0.5)  # top-left corner
    out = np.full(cal.thermal.width * cal.thermal.height, np.iinfo(np.uint16).max, np.uint16)
    np.minimum.at(out, idx[idx >= 0], depth[idx >= 0])
    out[out == np.iinfo(np.uint16).max] = 0
    return out.reshape(cal.thermal.shape)


@pytest.fixture(scope="module")
def rs_align() -> Iterator[RsAlign]:
    try:
        aligner = RsAlign(default_calibration())
    except ImportError as exc:
        pytest.skip(f"librealsense not available: {exc}")
    yield aligner
    aligner.close()


def test_rs_align_thermal_to_depth_maps_the_bottom_right_corner(
    rs_align: RsAlign, depth: NDArray[np.uint16]
) -> None:
    cal = rs_align.calibration
    thermal = thermal_index_image(cal)
    got = rs_align.thermal_to_depth(depth, thermal)
    assert got.shape == cal.depth.shape and got.dtype == np.uint16
    # librealsense's own mapping, written out: all but a handful of float32 roundings
    assert (got == rs_model_thermal_to_depth(cal, depth, thermal)).mean() >= 0.9999

    # a pixel-centre nearest sampler (ours): the corner sits J (0.5, 0.5) thermal px off the
    # centre, J = fx_thermal / fx_depth = 0.233 thermal px per depth px, so both pick the
    # same pixel with probability (1 - J / 2)^2 = 0.780 (reference-values.md: ~77 %).
    ours = Registration(cal).thermal_to_depth(depth, thermal)
    both = (ours.reason == Reason.OK) & (got > 0)
    same_centre = float((got[both] == ours.values[both]).mean())
    jac = cal.thermal.fx / cal.depth.fx
    assert abs(same_centre - (1 - jac / 2) ** 2) < 0.02, same_centre

    # a corner-convention nearest sampler (floor(x + 0.5) at u + 0.5, OpenCV distortion):
    # differs only where truncation widens row and column 0 and by the tangential terms
    # (reference-values.md: ~98.6 %)
    tu, tv, _ = numpy_reference(cal, depth, pixel_offset=(0.5, 0.5))
    idx, ok = nearest_index(cal, tu, tv)
    corner = np.where(ok, thermal.ravel()[np.where(ok, idx, 0)], 0)
    either = (got > 0) | (corner > 0)
    same_corner = float((got[either] == corner[either]).mean())
    assert same_corner >= 0.97, same_corner
    assert (got[both] == corner[both]).mean() >= 0.999

    # no occlusion test: the hot box bleeds onto the wall it hides from the thermal camera
    occluded = ours.reason == Reason.OCCLUDED
    assert occluded.sum() > 300
    assert (got[occluded] > 0).mean() >= 0.99
    assert not got[depth == 0].any()


def test_rs_align_depth_to_thermal_keeps_the_nearest_raw_depth(
    rs_align: RsAlign, depth: NDArray[np.uint16]
) -> None:
    cal = rs_align.calibration
    got = rs_align.depth_to_thermal(depth)
    assert got.shape == cal.thermal.shape and got.dtype == np.uint16
    # the smallest raw depth among the depth pixels whose top-left corner lands in the pixel
    assert (got == rs_model_depth_to_thermal(cal, depth)).mean() >= 0.9999

    # ours keeps Z in the thermal frame at pixel centres: in the depth frame it is within 1 %
    # of rs.align's value on >= 99 % of the pixels both fill (depth noise ~ z^2 makes the
    # minimum over a shifted set of depth pixels differ by a few mm)
    ours = Registration(cal).depth_to_thermal(depth)
    z_d = depth_frame_z(cal, ours.z_m)
    z_rs = got * cal.depth_scale_m
    both = np.isfinite(z_d) & (got > 0)
    assert abs(int(both.sum()) - int((got > 0).sum())) <= 0.01 * got.size
    assert abs(int(both.sum()) - int(np.isfinite(z_d).sum())) <= 0.01 * got.size
    close = np.abs(z_rs[both] - z_d[both]) <= 0.01 * z_d[both]
    assert close.mean() >= 0.99, close.mean()


def test_rs_extrinsics_are_column_major() -> None:
    try:
        rs = import_pyrealsense2()
    except ImportError as exc:
        pytest.skip(f"librealsense not available: {exc}")
    rotated = default_calibration()
    rot = rotation_from_euler(0.05, -0.08, 0.12)  # ~8 deg: R and R^T differ by ~16 deg
    tr = np.array([0.05, -0.02, 0.01])
    cal = Calibration(
        rotated.depth,
        rotated.thermal,
        rotated.depth_scale_m,
        RigidTransform(rot, tr, "thermal", "depth"),
    )
    transposed = Calibration(
        cal.depth, cal.thermal, cal.depth_scale_m, RigidTransform(rot.T, tr, "thermal", "depth")
    )
    point = np.array([0.3, -0.2, 1.5])
    want = cal.thermal_from_depth.apply(point)
    got = rs.rs2_transform_point_to_point(rs_extrinsics(rs, cal), point.tolist())
    np.testing.assert_allclose(got, want, atol=1e-6)
    wrong = rs.rs2_transform_point_to_point(rs_extrinsics(rs, cal, transpose=True), point.tolist())
    assert np.linalg.norm(np.subtract(wrong, want)) > 0.1

    # through rs.align: a slanted plane lands where R (not R^T) puts it
    v, u = np.mgrid[0:720, 0:1280]
    plane = (1200 + 0.4 * u + 0.2 * v).astype(np.uint16)
    thermal = thermal_index_image(cal)
    with RsAlign(cal) as aligner:
        got_t2d = aligner.thermal_to_depth(plane, thermal)
        got_d2t = aligner.depth_to_thermal(plane)
    assert (got_t2d > 0).mean() > 0.2
    assert (got_t2d == rs_model_thermal_to_depth(cal, plane, thermal)).mean() >= 0.999
    assert (got_t2d == rs_model_thermal_to_depth(transposed, plane, thermal)).mean() < 0.5
    assert (got_d2t == rs_model_depth_to_thermal(cal, plane)).mean() >= 0.999
    assert (got_d2t == rs_model_depth_to_thermal(transposed, plane)).mean() < 0.5


def test_rs_align_refuses_bad_input(rs_align: RsAlign, depth: NDArray[np.uint16]) -> None:
    with pytest.raises(ValueError, match="uint16"):
        rs_align.depth_to_thermal(depth.astype(np.float32))
    with pytest.raises(ValueError, match="thermal"):
        rs_align.thermal_to_depth(depth, np.zeros((60, 80), np.uint16))
