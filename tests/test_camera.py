"""Camera geometry: the paper's eqs (1)-(13), distortion, project/deproject, transforms."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from thermodepth.camera import (
    FrameMismatchError,
    Intrinsics,
    RigidTransform,
    camera_to_image_plane,
    distort,
    image_plane_to_pixel,
    monotonic_radius2,
    project_with_matrix,
    projection_matrix,
    rotation_from_euler,
    undistort,
    world_to_camera,
)

LEPTON = Intrinsics(160, 120, 150.5, 151.0, 80.3, 59.1, [-0.12, 0.05, 0.001, -0.0007, 0.01])
D435 = Intrinsics(1280, 720, 645.0, 645.0, 639.5, 359.5)

angles = st.floats(-np.pi, np.pi, allow_nan=False)


@given(angles, angles, angles)
def test_euler_is_passive_zxy(phi: float, theta: float, omega: float) -> None:
    # R = R1(z, phi) R2(x, theta) R3(y, omega), each a frame (passive) rotation.
    expected = Rotation.from_euler("ZXY", [-phi, -theta, -omega]).as_matrix()
    np.testing.assert_allclose(rotation_from_euler(phi, theta, omega), expected, atol=1e-12)


def test_euler_single_axes_match_printed_pattern() -> None:
    a = 0.3
    c, s = np.cos(a), np.sin(a)
    np.testing.assert_allclose(
        rotation_from_euler(a, 0, 0), [[c, s, 0], [-s, c, 0], [0, 0, 1]], atol=1e-15
    )
    np.testing.assert_allclose(
        rotation_from_euler(0, a, 0), [[1, 0, 0], [0, c, s], [0, -s, c]], atol=1e-15
    )
    np.testing.assert_allclose(
        rotation_from_euler(0, 0, a), [[c, 0, -s], [0, 1, 0], [s, 0, c]], atol=1e-15
    )
    # Fig. 3: turning the axes by +90 deg about z moves a point on +x onto -y.
    np.testing.assert_allclose(
        rotation_from_euler(np.pi / 2, 0, 0) @ [1, 0, 0], [0, -1, 0], atol=1e-15
    )


def _world_scene(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rot = rotation_from_euler(*rng.uniform(-0.3, 0.3, 3))
    t = rng.uniform(-0.2, 0.2, 3) + np.array([0, 0, 2.0])
    pts = rng.uniform([-0.5, -0.4, -0.5], [0.5, 0.4, 0.5], (200, 3))
    return pts, rot, t


def test_eq13_equals_composition_of_steps_and_opencv() -> None:
    rng = np.random.default_rng(1)
    pts_w, rot, t = _world_scene(rng)
    focal_m, pitch = 2.56e-3, (17e-6, 17e-6)  # Lepton 3: f ~ 2.56 mm, 17 um pixels
    pp = (79.5, 59.5)
    steps = image_plane_to_pixel(
        camera_to_image_plane(world_to_camera(pts_w, rot, t), focal_m), pitch, pp
    )
    eq13 = project_with_matrix(pts_w, projection_matrix(focal_m, pitch, pp, rot, t))
    np.testing.assert_allclose(eq13, steps, atol=1e-9)
    k = np.array([[focal_m / pitch[0], 0, pp[0]], [0, focal_m / pitch[1], pp[1]], [0, 0, 1]])
    cv, _ = cv2.projectPoints(pts_w, cv2.Rodrigues(rot)[0], t, k, None)
    np.testing.assert_allclose(eq13, cv.reshape(-1, 2), atol=1e-6)


@pytest.mark.parametrize("intr", [LEPTON, D435], ids=["lepton", "d435"])
def test_project_matches_opencv(intr: Intrinsics) -> None:
    rng = np.random.default_rng(2)
    pts = rng.uniform([-0.6, -0.45, 0.3], [0.6, 0.45, 3.0], (5000, 3))
    ours = intr.project(pts)
    cv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), intr.matrix, intr.distortion)
    np.testing.assert_allclose(ours, cv.reshape(-1, 2), atol=1e-6)


def test_deproject_matches_opencv_undistort() -> None:
    u, v = LEPTON.pixel_grid()
    px = np.stack([u.ravel(), v.ravel()], axis=-1)
    x, y = LEPTON.normalized_from_pixels(px)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    # OpenCV 4 names the iterative variant undistortPointsIter; OpenCV 5 folds it in
    undistort_iter = getattr(cv2, "undistortPointsIter", cv2.undistortPoints)
    cv = undistort_iter(
        px.reshape(-1, 1, 2), LEPTON.matrix, LEPTON.distortion, None, None, criteria=crit
    ).reshape(-1, 2)
    # in pixels of the undistorted image: 1e-6 px
    np.testing.assert_allclose(x * LEPTON.fx, cv[:, 0] * LEPTON.fx, atol=1e-6)
    np.testing.assert_allclose(y * LEPTON.fy, cv[:, 1] * LEPTON.fy, atol=1e-6)


@settings(max_examples=200)
@given(st.floats(-0.5, 159.5), st.floats(-0.5, 119.5), st.floats(0.2, 20.0, allow_nan=False))
def test_round_trip_pixel_depth_pixel(u: float, v: float, z: float) -> None:
    p = LEPTON.deproject([u, v], z)
    assert p[2] == pytest.approx(z)
    np.testing.assert_allclose(LEPTON.project(p), [u, v], atol=1e-9)


def test_round_trip_point_pixel_point() -> None:
    rng = np.random.default_rng(3)
    pts = rng.uniform([-0.5, -0.4, 0.5], [0.5, 0.4, 3.0], (1000, 3))
    back = LEPTON.deproject(LEPTON.project(pts), pts[:, 2])
    np.testing.assert_allclose(back, pts, atol=1e-12)


def test_distort_undistort_inverse_for_strong_distortion() -> None:
    dist = [-0.3, 0.12, 0.002, -0.001, -0.02]
    rng = np.random.default_rng(4)
    x, y = rng.uniform(-0.6, 0.6, (2, 1000))
    xu, yu = undistort(*distort(x, y, dist), dist)
    np.testing.assert_allclose(xu, x, atol=1e-12)
    np.testing.assert_allclose(yu, y, atol=1e-12)


def test_projection_refuses_points_where_distortion_folds() -> None:
    # k1 < 0 alone: r (1 + k1 r^2) peaks at r^2 = -1/(3 k1); far points would fold inward.
    intr = Intrinsics(160, 120, 150.0, 150.0, 79.5, 59.5, [-0.2, 0, 0, 0, 0])
    r2max = monotonic_radius2(intr.distortion)
    assert r2max == pytest.approx(1 / 0.6, rel=1e-3)
    far = np.array([[3.0, 0.0, 1.0]])  # r^2 = 9: polynomial gives r_d = 3(1 - 1.8) < 0
    assert np.all(np.isnan(intr.project(far)))
    near = np.array([[1.0, 0.0, 1.0]])
    assert np.all(np.isfinite(intr.project(near)))
    # a point behind the camera never projects
    assert np.all(np.isnan(intr.project([[0.0, 0.0, -1.0]])))


def test_contains_uses_pixel_edges() -> None:
    inside = LEPTON.contains([[-0.5, -0.5], [159.49, 119.49], [80, 60]])
    outside = LEPTON.contains([[-0.51, 0], [159.5, 0], [0, 119.5]])
    assert inside.all() and not outside.any()


def test_intrinsics_reject_bad_focal_length() -> None:
    with pytest.raises(ValueError, match="focal"):
        Intrinsics(160, 120, 0.0, 150.0, 80, 60)


def _transform(rng: np.random.Generator, to: str, frm: str) -> RigidTransform:
    return RigidTransform(
        Rotation.random(random_state=rng).as_matrix(), rng.normal(size=3), to, frm
    )


def test_transform_composition_and_inverse() -> None:
    rng = np.random.default_rng(5)
    b_from_a = _transform(rng, "b", "a")
    c_from_b = _transform(rng, "c", "b")
    c_from_a = c_from_b @ b_from_a
    assert c_from_a.name == "c_from_a"
    p = rng.normal(size=(10, 3))
    np.testing.assert_allclose(c_from_a.apply(p), c_from_b.apply(b_from_a.apply(p)), atol=1e-12)
    np.testing.assert_allclose((b_from_a.inverse() @ b_from_a).matrix, np.eye(4), atol=1e-12)
    assert b_from_a.inverse().name == "a_from_b"
    np.testing.assert_allclose(c_from_a.matrix, c_from_b.matrix @ b_from_a.matrix, atol=1e-12)


def test_composing_mismatched_frames_raises() -> None:
    rng = np.random.default_rng(6)
    with pytest.raises(FrameMismatchError, match="'a' != 'c'"):
        _ = _transform(rng, "b", "a") @ _transform(rng, "c", "d")


def test_transform_rejects_non_rotation() -> None:
    with pytest.raises(ValueError, match="orthonormal"):
        RigidTransform(np.diag([1.0, 1.0, -1.0]), np.zeros(3), "b", "a")


def test_angle_distance_and_field_of_view() -> None:
    # 0.3 rad about a tilted axis, 5 cm apart
    rot = Rotation.from_rotvec(0.3 * np.array([1.0, 2.0, 2.0]) / 3.0).as_matrix()
    t = RigidTransform(rot, [0.03, 0.0, -0.04], "b", "a")
    assert t.angle_deg == pytest.approx(np.degrees(0.3), abs=1e-9)
    assert t.distance_m == pytest.approx(0.05)
    assert RigidTransform.identity("b", "a").angle_deg == 0.0
    assert LEPTON.hfov_deg == pytest.approx(2 * np.degrees(np.arctan(80 / 150.5)))
    assert 55.5 < LEPTON.hfov_deg < 56.5  # the Lepton 3 datasheet: 56 deg
