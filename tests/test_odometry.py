"""Depth odometry on simulated walks in a furnished room, loop closure, lost tracking; the
trajectory's absolute trajectory error and its TUM file.

The room: 4 x 4 x 2.5 m with nine boxes along its walls, so that every view of it (the
camera 1.2 m above the floor, looking 15 degrees down) has surfaces facing three ways. The
depth camera is the simulated D435 at 640 x 480 (848 x 480 for the two-frame test), noise
(sigma_z = 0.08 z^2 / (fx 0.05 m): 4 mm at 1 m, 17 mm at 2 m per pixel) and stereo shadow
on; every walk has a fixed seed, so its figures are the same from run to run.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from thermodepth.camera import RigidTransform
from thermodepth.errors import FieldError, InputError
from thermodepth.mapping.odometry import (
    DepthOdometry,
    OdometryOptions,
    _exp,
    _inverse,
    depth_odometry,
    optimise_pose_graph,
)
from thermodepth.sim import Material, Rig, Scene, box
from thermodepth.sim.d435 import depth_units
from thermodepth.trajectory import Trajectory, absolute_trajectory_error

FPS = 30.0
Path3 = Callable[[float], RigidTransform]


def room() -> Scene:
    """The furnished room: floor at y = 1.2 m, ceiling at -1.3 m (y is down), walls at
    x, z = +-2 m; boxes (x, z, width, height, depth) standing on the floor, and a shelf."""
    m = Material(295.0)
    rects = box([0, -0.05, 0], (4.0, 2.5, 4.0), m, name="room")
    boxes = [
        (-1.5, 1.5, 0.6, 0.8, 0.5), (1.4, 1.6, 0.8, 0.5, 0.6), (1.6, -1.2, 0.5, 1.0, 0.5),
        (-1.2, -1.6, 1.0, 0.6, 0.5), (0.2, 1.75, 0.5, 0.3, 0.4), (-1.75, -0.2, 0.4, 0.7, 0.6),
        (1.75, 0.3, 0.4, 0.4, 0.8), (0.0, -1.75, 0.5, 0.5, 0.4),
    ]  # fmt: skip
    for k, (x, z, sx, sy, sz) in enumerate(boxes):
        rects += box([x, 1.2 - sy / 2, z], (sx, sy, sz), m, name=f"box{k}")
    rects += box([0.8, -0.3, 1.9], (0.8, 0.1, 0.2), m, name="shelf")
    return Scene(tuple(rects))


def view(
    yaw_deg: float, pitch_deg: float, position_m: tuple[float, float, float]
) -> RigidTransform:
    """``world_from_depth`` turned by yaw (about y, down) then pitch (about x; negative looks
    down), at ``position_m``."""
    rot = Rotation.from_euler("YX", [yaw_deg, pitch_deg], degrees=True).as_matrix()
    return RigidTransform(rot, np.asarray(position_m, np.float64), "world", "depth")


def circle(radius_m: float, period_s: float) -> Path3:
    """A walk once round a circle from the room's centre (looking out, turning with it, the
    pitch and height gently varying); it ends where it started."""

    def pose(t: float) -> RigidTransform:
        a = 2 * np.pi * t / period_s
        position = (radius_m * np.sin(a), 0.1 * np.sin(3 * a), radius_m * (np.cos(a) - 1))
        return view(np.degrees(a), -(15 + 5 * np.sin(2 * a)), position)

    return pose


def depth_rig(mode: str = "640x480", seed: int = 0) -> Rig:
    return Rig.of_cameras(room(), view(0, -15, (0, 0, 0)), depth=mode, seed=seed)


def depth_frame(rig: Rig, pose: RigidTransform) -> NDArray[np.uint16]:
    """A noisy Z16 frame of the rig's depth camera at ``pose``."""
    cal = rig.calibration
    seen = rig._depth_views(pose)
    return depth_units(
        seen.hits.z_m, cal.depth.fx, cal.depth_scale_m, rig.depth_model, rig.rng, seen.shadow
    )


def walk(rig: Rig, path: Path3, n: int) -> Iterator[tuple[float, NDArray[np.uint16]]]:
    """``n`` depth frames at 30 fps along ``path``."""
    for k in range(n):
        yield k / FPS, depth_frame(rig, path(k / FPS))


def truth_of(path: Path3, n: int) -> Trajectory:
    times = np.arange(n) / FPS
    return Trajectory.of_poses(times, [path(t) for t in times])


def relative_error(estimate: RigidTransform, truth: RigidTransform) -> tuple[float, float]:
    """(distance m, angle deg) between two poses of one frame in another."""
    err = np.linalg.inv(truth.matrix) @ estimate.matrix
    cos = (np.trace(err[:3, :3]) - 1.0) / 2.0
    return float(np.linalg.norm(err[:3, 3])), float(np.degrees(np.arccos(np.clip(cos, -1, 1))))


# -- ICP -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("yaw_deg", "step_m"),
    [(2.0, (0.03, 0.01, -0.01)), (-4.0, (-0.01, 0.0, 0.04))],
)
def test_icp_recovers_a_known_motion(yaw_deg: float, step_m: tuple[float, float, float]) -> None:
    # two 848x480 frames, the second moved by a few cm and degrees: within 2 mm and 0.1 deg
    rig = depth_rig("848x480")
    a = view(30, -15, (0.1, 0.0, -0.2))
    b = view(30 + yaw_deg, -14, tuple(np.add((0.1, 0.0, -0.2), step_m)))
    cal = rig.calibration
    frames = [(0.0, depth_frame(rig, a)), (1 / FPS, depth_frame(rig, b))]
    odo = depth_odometry(frames, cal.depth, cal.depth_scale_m)
    distance_m, angle_deg = relative_error(odo.trajectory.pose(1), a.inverse() @ b)
    assert distance_m < 0.002
    assert angle_deg < 0.1
    assert odo.fitness[1] > 0.8
    assert odo.lost == ()


# -- walks -----------------------------------------------------------------------------------


def test_a_short_walk_tracks_within_a_few_millimetres() -> None:
    # 1 s along a sixth of a 0.5 m circle (2 cm and 2 degrees a frame): ATE under 1 mm
    # (0.28 mm measured, 0.66 mm at most, 0.07 degrees)
    rig = depth_rig()
    path = circle(0.5, 6.0)
    n = 30
    cal = rig.calibration
    odo = depth_odometry(walk(rig, path, n), cal.depth, cal.depth_scale_m)
    ate = absolute_trajectory_error(odo.trajectory, truth_of(path, n))
    assert ate["rmse_m"] < 0.001
    assert ate["max_m"] < 0.002
    assert ate["rotation_max_deg"] < 0.2
    assert len(odo.keyframes) >= 4  # a new keyframe every 10 degrees
    assert odo.lost == ()


def test_loop_closure_removes_the_drift_of_a_loop() -> None:
    # once round a 0.5 m circle in 3 s: the odometry alone drifts several mm by the end; loop
    # closure ties the last keyframes to the first and the pose graph spreads the correction
    # (measured: drift 4.4 mm -> 0.05 mm, ATE 1.9 mm -> 1.1 mm)
    n = 91  # frame 90 is back at the start
    path = circle(0.5, (n - 1) / FPS)
    rig = depth_rig()
    cal = rig.calibration
    with_loops, without = (
        DepthOdometry(cal.depth, cal.depth_scale_m, OdometryOptions(loop_closure=lc))
        for lc in (True, False)
    )
    for t, depth in walk(rig, path, n):
        with_loops.track(t, depth)
        without.track(t, depth)
    truth = truth_of(path, n)
    results = {"with": with_loops.result(), "without": without.result()}
    drift_m = {
        k: relative_error(r.trajectory.pose(n - 1), r.trajectory.pose(0))[0]
        for k, r in results.items()
    }
    ate_m = {
        k: absolute_trajectory_error(r.trajectory, truth)["rmse_m"] for k, r in results.items()
    }
    assert results["without"].loops == ()
    assert len(results["with"].accepted_loops) >= 1
    assert results["with"].accepted_loops[0].earlier == 0
    assert all(lc.keyframe - lc.earlier >= 10 for lc in results["with"].loops)
    assert drift_m["without"] > 0.002  # long enough to drift
    assert drift_m["with"] < 0.25 * drift_m["without"]
    assert ate_m["with"] < 0.8 * ate_m["without"]
    assert ate_m["with"] < 0.002


# -- lost tracking ---------------------------------------------------------------------------


def test_frames_without_depth_are_reported_and_bridged() -> None:
    # no depth in the first frame (the world starts at the next) and in frame 6 (its pose
    # follows the constant-velocity prediction); every frame gets a pose
    rig = depth_rig()
    path = circle(0.5, 6.0)
    blank = np.zeros(rig.calibration.depth.shape, np.uint16)
    frames = [(t, blank if k in (0, 6) else d) for k, (t, d) in enumerate(walk(rig, path, 12))]
    cal = rig.calibration
    odo = depth_odometry(frames, cal.depth, cal.depth_scale_m)
    assert [(lf.frame, lf.action) for lf in odo.lost] == [(0, "held"), (6, "constant velocity")]
    assert "0 points" in odo.lost[1].reason
    assert odo.keyframes[0] == 1
    assert np.isnan(odo.fitness[6]) and np.all(odo.fitness[[2, 5, 7, 11]] > 0.7)
    # frame 0 is held at frame 1's pose, the world's origin; the others are within 2 mm of the
    # truth, frame 6 too (measured: 0.6 mm at most; frame 6 0.6 mm)
    assert odo.keyframe_of_frame[0] == -1
    np.testing.assert_array_equal(odo.trajectory.pose(0).matrix, np.eye(4))
    truth = truth_of(path, 12)
    world = truth.pose(1)  # the estimate's world: frame 1's camera
    for k in range(1, 12):
        distance_m, _ = relative_error(odo.trajectory.pose(k), world.inverse() @ truth.pose(k))
        assert distance_m < 0.002, k


def test_a_long_blackout_restarts_from_a_new_keyframe() -> None:
    # depth gone for 7 frames while the rig turns 120 degrees: 5 frames by constant velocity
    # (none here: the rig stood still), then held; the first frame back does not fit the old
    # keyframe and tracking starts afresh from it
    rig = depth_rig()
    a, b = view(0, -15, (0, 0, 0)), view(120, -15, (0.5, 0, 0.3))
    blank = np.zeros(rig.calibration.depth.shape, np.uint16)
    depths = [depth_frame(rig, a)] * 2 + [blank] * 7 + [depth_frame(rig, b)] * 2
    cal = rig.calibration
    odo = depth_odometry(enumerate(depths), cal.depth, cal.depth_scale_m)
    actions = [lf.action for lf in odo.lost]
    assert actions[:5] == ["constant velocity"] * 5
    assert actions[5:7] == ["held"] * 2
    assert actions[7].startswith("restarted") and "poor fit" in odo.lost[7].reason
    assert odo.keyframes == (0, 9)
    assert odo.fitness[10] > 0.9  # tracking again
    assert len(odo.trajectory) == 11
    summary = odo.summary()
    assert summary["lost_frames"] == {"constant velocity": 5, "held": 2, "restarted": 1}
    assert (summary["poses"], summary["keyframes"]) == (11, 2)
    assert summary["fitness_median"] > 0.9


def test_bad_frames_and_options_raise_one_clear_error() -> None:
    rig = depth_rig()
    cal = rig.calibration
    odo = DepthOdometry(cal.depth, cal.depth_scale_m)
    good = np.zeros(cal.depth.shape, np.uint16)
    with pytest.raises(InputError, match=r"depth frame 0: float64 pixels"):
        odo.track(0.0, good.astype(np.float64))
    with pytest.raises(InputError, match=r"depth frame 0: shape \(10, 10\)"):
        odo.track(0.0, good[:10, :10])
    odo.track(1.0, good)
    with pytest.raises(InputError, match=r"depth frame 1: time 1.0 s does not follow"):
        odo.track(1.0, good)
    with pytest.raises(FieldError, match="min_fitness"):
        OdometryOptions(min_fitness=1.5)
    with pytest.raises(FieldError, match="iterations"):
        DepthOdometry(cal.depth, cal.depth_scale_m, OdometryOptions(iterations=(3,) * 7))


# -- the pose graph --------------------------------------------------------------------------


def ring(k: int = 40) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Poses (k, 4, 4) once round a 1 m circle, turning with it, and the graph's edges: one
    between each two successive poses and a loop from the last to the first."""
    poses = np.array([view(360.0 * i / k, 0, (np.sin(2 * np.pi * i / k), 0,
                                               np.cos(2 * np.pi * i / k))).matrix
                      for i in range(k)])  # fmt: skip
    return poses, np.array([(i, i + 1) for i in range(k - 1)] + [(0, k - 1)])


def test_pose_graph_recovers_consistent_poses_from_a_drifted_start() -> None:
    # exact measurements, every pose but the first knocked off by ~5 cm / 3 deg: the graph
    # optimum is the truth, found to numerical precision
    truth, edges = ring()
    measured = np.array([_inverse(truth[i]) @ truth[j] for i, j in edges])
    rng = np.random.default_rng(2)
    start = np.array([truth[0]] + [_exp(rng.normal(0, 0.05, 6)) @ p for p in truth[1:]])
    info = np.tile(np.diag([1e4, 1e4, 1e4, 1e3, 1e3, 1e3]), (len(edges), 1, 1))
    out = optimise_pose_graph(start, edges, measured, info)
    np.testing.assert_allclose(out, truth, atol=1e-7)


def test_pose_graph_closes_a_drifted_chain() -> None:
    # odometry edges each off by ~3 mm / 0.2 deg, the chain drifting ~4 cm by its end; one
    # exact loop edge from the last pose to the first: the end comes back to within a tenth
    truth, edges = ring()
    measured = np.array([_inverse(truth[i]) @ truth[j] for i, j in edges])
    rng = np.random.default_rng(3)
    chain = [truth[0]]
    for e in range(len(truth) - 1):
        measured[e] = measured[e] @ _exp(rng.normal(0, 0.003, 6))
        chain.append(chain[-1] @ measured[e])
    drifted = np.array(chain)
    info = np.tile(np.eye(6) * 1e5, (len(edges), 1, 1))
    out = optimise_pose_graph(drifted, edges, measured, info)
    loop_before = np.linalg.norm((_inverse(drifted[0]) @ drifted[-1] - measured[-1])[:3, 3])
    loop_after = np.linalg.norm((_inverse(out[0]) @ out[-1] - measured[-1])[:3, 3])
    np.testing.assert_array_equal(out[0], drifted[0])  # the first pose fixes the world
    assert loop_before > 0.02
    assert loop_after < 0.1 * loop_before


# -- the absolute trajectory error and the TUM file -------------------------------------------


def curve(n: int = 60) -> Trajectory:
    t = np.linspace(0.0, 6.0, n)
    rot = Rotation.from_euler("YX", np.column_stack([t, 0.3 * np.sin(t)])).as_matrix()
    return Trajectory(t, rot, np.column_stack([np.sin(t), 0.2 * t, np.cos(t)]))


def test_ate_of_a_moved_copy_is_zero() -> None:
    # the same path in another world frame (turned 125 deg, moved), sampled between the
    # truth's poses: the alignment recovers the frame, the errors vanish
    truth = curve()
    g = Rotation.from_rotvec([0.4, -1.2, 1.7]).as_matrix()
    shift = np.array([1.0, -2.0, 3.0])
    times = np.linspace(0.5, 5.5, 23)
    rot, pos = truth.poses_at(times)
    moved = Trajectory(times, g @ rot, pos @ g.T + shift)
    ate = absolute_trajectory_error(moved, truth)
    assert ate["max_m"] < 1e-12
    assert ate["rotation_max_deg"] < 1e-9
    align = ate["truth_from_estimate"]
    np.testing.assert_allclose(align.rotation, g.T, atol=1e-12)
    np.testing.assert_allclose(align.apply(shift), 0.0, atol=1e-12)


def test_ate_measures_a_known_error() -> None:
    # positions exact, every orientation turned 2 degrees about the camera's own axis: 0 m
    # and exactly 2 degrees; one position 10 cm off moves the others by under its share
    truth = curve()
    turned = truth.rotations @ Rotation.from_euler("Z", 2.0, degrees=True).as_matrix()
    ate = absolute_trajectory_error(Trajectory(truth.times_s, turned, truth.translations_m), truth)
    assert ate["max_m"] < 1e-12
    for key in ("rotation_rmse_deg", "rotation_median_deg", "rotation_max_deg"):
        assert ate[key] == pytest.approx(2.0, abs=1e-9)
    pos = truth.translations_m.copy()
    pos[30, 0] += 0.1
    ate = absolute_trajectory_error(Trajectory(truth.times_s, truth.rotations, pos), truth)
    assert 0.09 < ate["max_m"] < 0.1
    assert ate["median_m"] < 0.1 / len(pos) * 2
    assert ate["rmse_m"] == pytest.approx(0.1 / np.sqrt(len(pos)), rel=0.05)


def test_ate_needs_the_truth_over_the_estimate() -> None:
    truth = curve()
    late = Trajectory(truth.times_s + 1.0, truth.rotations, truth.translations_m)
    with pytest.raises(InputError, match="beyond the truth's"):
        absolute_trajectory_error(late, truth)


def test_tum_round_trip(tmp_path: Path) -> None:
    traj = curve(25)
    back = Trajectory.load_tum(traj.save_tum(tmp_path / "walk.txt"))
    np.testing.assert_allclose(back.times_s, traj.times_s, rtol=1e-9)
    np.testing.assert_allclose(back.translations_m, traj.translations_m, atol=1e-8)
    np.testing.assert_allclose(back.rotations, traj.rotations, atol=1e-8)


@pytest.mark.parametrize(
    ("line", "says"),
    [
        ("0.2 1 2 3 0 0 0 one", "not a number"),
        ("0.2 1 2 3 0 0 1", "7 fields; a TUM pose has 8"),
        ("0.2 1 2 3 0 0 0 0", "unit quaternion"),
        ("0.1 1 2 3 0 0 0 1", "does not increase"),
    ],
)
def test_a_bad_tum_line_is_one_error_naming_file_and_line(
    tmp_path: Path, line: str, says: str
) -> None:
    path = tmp_path / "walk.txt"
    path.write_text(f"# a walk\n0.1 0 0 0 0 0 0 1\n{line}\n0.3 0 0 0 0 0 0 1\n")
    with pytest.raises(InputError) as err:
        Trajectory.load_tum(path)
    assert str(err.value).startswith(f"{path}:3: ")
    assert says in str(err.value)
