"""The ray caster's culling: testing each rect only on the rows and columns of the grid that
can see it gives what testing every rect on every ray gives, bit for bit, wherever the camera
stands (rects behind it, beside it, crossing its plane, through its centre)."""

from __future__ import annotations

import numpy as np
import pytest

from thermodepth.camera import Intrinsics, RigidTransform, pixel_rays, rotation_from_euler
from thermodepth.sim import camera_pose, default_calibration, kernels
from thermodepth.sim.raycast import Hits, _bboxes, blocked, cast, rect_params
from thermodepth.sim.scene import Material, Rect, Scene
from thermodepth.sim.walkaround import machine_scene, room_scene

CAL = default_calibration()
COARSE_DEPTH = Intrinsics(128, 72, 64.5, 64.5, 63.5, 35.5)
CAMERAS = {"depth": (COARSE_DEPTH, 1), "thermal": (CAL.thermal, 2)}  # thermal: distortion


def _every_rect_on_every_ray(
    scene: Scene, camera_from_world: RigidTransform, intr: Intrinsics, ss: int
) -> Hits:
    xs, ys = pixel_rays(intr, ss)
    bbox = np.tile([0, xs.shape[0] - 1, 0, xs.shape[1] - 1], (len(scene.rects), 1))
    z, s, q, rng = (np.empty(xs.shape) for _ in range(4))
    ids = np.empty(xs.shape, np.int64)
    kernels.cast_grid(xs, ys, rect_params(scene, camera_from_world), bbox, z, ids, s, q, rng)
    return Hits(z, ids, s, q, rng)


def _poses(scene: str, n: int, seed: int) -> list[RigidTransform]:
    """Eyes anywhere in the room (or the hall round the machine), looking anywhere."""
    rng = np.random.default_rng(seed)
    lo, hi = (
        ([-1.9, -2.45, -1.9], [1.9, -0.05, 1.9])
        if scene == "room"
        else ([-3, -3, -3], [2.7, -0.1, 2.9])
    )
    poses = []
    for _ in range(n):
        eye = rng.uniform(lo, hi)
        yaw, pitch, roll = rng.uniform(-180, 180), rng.uniform(-89, 89), rng.uniform(-30, 30)
        poses.append(camera_pose(0.0, yaw, pitch, roll, target_m=eye).inverse())
    return poses


@pytest.mark.parametrize("camera", list(CAMERAS))
@pytest.mark.parametrize("scene", ["room", "machine"])
def test_culling_changes_no_hit(scene: str, camera: str) -> None:
    built = room_scene() if scene == "room" else machine_scene()
    intr, ss = CAMERAS[camera]
    culled = 0
    for pose in _poses(scene, 25, seed=len(scene)):
        got, want = cast(built, pose, intr, ss), _every_rect_on_every_ray(built, pose, intr, ss)
        for field in ("z_m", "rect", "s_m", "q_m", "range_m"):
            np.testing.assert_array_equal(getattr(got, field), getattr(want, field))
        box = _bboxes(built, pose, intr, ss)
        culled += int(np.sum((box[:, 0] > box[:, 1]) | (box[:, 2] > box[:, 3])))
    assert culled > 25 * len(built.rects) // 3  # most rects are out of any one view


def _rect(center: list[float], u: list[float], v: list[float], half: float = 0.5) -> Rect:
    return Rect(np.array(center), np.array(u), np.array(v), half, half, Material(300.0))


_AXES = rotation_from_euler(0.7, -1.1, 2.3)
FAR = _rect([0.0, 0.0, 3.0], [1, 0, 0], [0, 1, 0], 5.0)
EDGE_CASES = {
    # walls beside the camera reaching behind it, one just behind it
    "crossing": (
        _rect([0.45, 0.0, 0.1], [0, 0, 1], [0, 1, 0]),
        _rect([-0.3, 0.0, 0.3], [0, 0.6, 0.8], [0, 0.8, -0.6]),
        _rect([0.0, 0.0, -0.01], [1, 0, 0], [0, 1, 0]),
        FAR,
    ),
    # floors a micrometre below the eye (tested on every ray) and 3 um above it (clipped
    # a fraction of that in front of the camera)
    "by the centre": (
        _rect([0.0, 1e-6, 0.2], [1, 0, 0], [0, 0, 1]),
        _rect([0.0, -3e-6, 0.2], [1, 0, 0], [0, 0, 1]),
        FAR,
    ),
    # a rect through the camera centre: seen edge on, but rounding puts its plane a hair
    # off the centre, so rays meet it a hair in front (~1e-16 m; met on every ray)
    "through the centre": (_rect(list(-_AXES @ [0.1, -0.05, 0.0]), *_AXES.T[:2].tolist()), FAR),
}


@pytest.mark.parametrize("camera", list(CAMERAS))
@pytest.mark.parametrize("case", list(EDGE_CASES))
def test_rects_crossing_the_camera_plane_or_by_its_centre(case: str, camera: str) -> None:
    scene = Scene(EDGE_CASES[case])
    intr, ss = CAMERAS[camera]
    rng = np.random.default_rng(4)
    seen: set[int] = set()
    for k in range(12):
        pose = (camera_pose(0.0, *rng.uniform(-25, 25, 3)) if k else camera_pose(0.0)).inverse()
        got, want = cast(scene, pose, intr, ss), _every_rect_on_every_ray(scene, pose, intr, ss)
        for field in ("z_m", "rect", "s_m", "q_m"):
            np.testing.assert_array_equal(getattr(got, field), getattr(want, field))
        seen |= set(np.unique(got.rect).tolist())
    expected = {"crossing": {0, 1, 3}, "by the centre": {0, 1}, "through the centre": {0, 1}}
    assert expected[case] <= seen


def test_lines_of_sight_inside_the_image_meet_only_the_rects_it_sees() -> None:
    # blocked(in_image=...) tests only the rects that reach into the image: the same answer
    scene, intr = room_scene(), CAL.thermal
    rng = np.random.default_rng(7)
    for pose in _poses("room", 12, seed=3):
        u = rng.uniform(-0.5, intr.width - 0.5, 4000)
        v = rng.uniform(-0.5, intr.height - 0.5, 4000)
        points = intr.deproject(np.stack([u, v], axis=-1), rng.uniform(0.1, 6.0, 4000))
        got = blocked(scene, pose, points, in_image=intr)
        np.testing.assert_array_equal(got, blocked(scene, pose, points))
        assert 0 < got.sum() < got.size
