"""The simulated walk for 3D thermal mapping: directional emissivity and reflections, the
microbolometer's smear, the handheld walk, its recording and its truth."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from thermodepth.camera import Intrinsics, RigidTransform
from thermodepth.cli import app
from thermodepth.frames import DepthFrame, FfcState, ThermalFrame
from thermodepth.io.recording import Recording
from thermodepth.radiometry import (
    ZERO_C_IN_K,
    atmospheric_transmission,
    fresnel_emissivity,
    fresnel_index,
)
from thermodepth.sim import Material, Rect, Rig, Scene, box, camera_pose, plate_scene
from thermodepth.sim.lepton import bolometer_memory, radiance_table
from thermodepth.sim.raycast import cast
from thermodepth.sim.scene import RectArrays, occlusion_scene
from thermodepth.sim.shading import aperture_radiance, surface_properties
from thermodepth.sim.walk_truth import nearest_rect, read_walk_truth, surface_samples
from thermodepth.sim.walkaround import (
    WalkConfig,
    machine_scene,
    part_hotspot,
    room_scene,
    simulate_walkaround,
    walk_rig,
    walkaround_path,
    walkaround_trajectory,
)

runner = CliRunner()
K = ZERO_C_IN_K
EX, EY, EZ = np.eye(3)

# -- Fresnel emissivity ------------------------------------------------------------------------


def test_fresnel_emissivity_of_glass_matches_the_published_values() -> None:
    # glass, n = 1.5: R0 = ((n - 1) / (n + 1))^2 = 0.04 (Born & Wolf 1.5; Modest ch. 2)
    assert fresnel_index(0.96) == pytest.approx(1.5, abs=1e-12)
    assert fresnel_emissivity(1.0, 0.96) == pytest.approx(0.96, abs=1e-12)
    # Brewster's angle atan(1.5) = 56.31 deg: R_p = 0, so eps = 1 - R_s / 2 with
    # R_s = ((n^2 - 1) / (n^2 + 1))^2 = (1.25 / 3.25)^2 = 0.147929
    brewster = np.arctan(1.5)
    assert np.degrees(brewster) == pytest.approx(56.31, abs=0.01)
    assert fresnel_emissivity(np.cos(brewster), 0.96) == pytest.approx(1 - 0.147929 / 2, abs=1e-6)
    # by hand: at 60 deg R_s = 0.17656, R_p = 0.00180 -> 0.91081; at 80 deg R_s = 0.53860,
    # R_p = 0.23682 -> 0.61229 (to the 5th decimal)
    assert fresnel_emissivity(np.cos(np.radians(60)), 0.96) == pytest.approx(0.91081, abs=2e-5)
    assert fresnel_emissivity(np.cos(np.radians(80)), 0.96) == pytest.approx(0.61229, abs=2e-5)


@pytest.mark.parametrize("eps_n", [0.3, 0.84, 0.95, 1.0])
def test_fresnel_emissivity_holds_to_60_degrees_then_falls(eps_n: float) -> None:
    cos = np.cos(np.radians([0.0, 30.0, 60.0, 80.0, 89.9]))
    eps = fresnel_emissivity(cos, eps_n)
    assert eps[0] == pytest.approx(eps_n, abs=1e-12)  # normal: the material's
    assert eps[1] == pytest.approx(eps_n, abs=0.01)  # within 0.01 up to 30 deg
    if eps_n == 1.0:  # a blackbody: the same at every angle
        np.testing.assert_allclose(eps, 1.0, atol=1e-12)
    else:
        assert eps[4] < 0.05  # none at grazing


# -- rendering ---------------------------------------------------------------------------------


@pytest.mark.parametrize("scene", [plate_scene(chip_temp_c=70.0), occlusion_scene()])
def test_a_default_material_renders_as_before(scene: Scene) -> None:
    """L_ap = tau [eps L(T) + (1 - eps) L(T_amb)] + (1 - tau) L(T_amb), bit for bit."""
    assert not scene.has_optics
    pose = camera_pose(1.5, yaw_deg=10.0).inverse()
    intr = Intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)
    hits = cast(scene, pose, intr, 2)
    table = radiance_table()
    temp, emis, _ = surface_properties(scene, hits)
    l_amb = float(table.to_radiance(scene.ambient_temp_k))
    tau = atmospheric_transmission(
        np.where(hits.rect >= 0, hits.range_m, 0.0), scene.ambient_temp_k, 0.5
    )
    expected = tau * (emis * table.to_radiance(temp) + (1.0 - emis) * l_amb) + (1.0 - tau) * l_amb
    np.testing.assert_array_equal(aperture_radiance(scene, hits, table), expected)


def _mirror_scene(specular: bool) -> Scene:
    """A mirror (emissivity 0.1, at 20 C) 2 m ahead facing the camera, a hot box (80 C) 1 m
    ahead and 0.5 m right, facing it."""
    mirror = Material(293.15, 0.1, 0.5, "mirror", specular=specular)
    rects = [Rect(np.array([0.0, 0.0, 2.0]), EX, EY, 1.5, 1.0, mirror, name="mirror")]
    rects += box([0.5, 0.0, 1.0], (0.1, 0.1, 0.1), Material(353.15, 0.95, name="hot"), name="hot")
    return Scene(tuple(rects), 293.15, 0.5)


def test_a_mirror_shows_a_hot_box_where_it_reflects_it() -> None:
    # one ray from the eye at the origin to the mirror image of the box's face centre
    # (0.5, 0, 1.05) in the plane z = 2: (0.5, 0, 2.95)
    image = np.array([0.5, 0.0, 2.95])
    yaw = np.degrees(np.arctan2(image[0], image[2]))
    pose = camera_pose(float(np.linalg.norm(image)), yaw_deg=yaw, target_m=image)
    np.testing.assert_allclose(pose.translation_m, 0.0, atol=1e-12)  # the eye at the origin
    pixel = Intrinsics(1, 1, 100.0, 100.0, 0.0, 0.0)
    table = radiance_table()
    seen = {}
    for specular in (False, True):
        scene = _mirror_scene(specular)
        hits = cast(scene, pose.inverse(), pixel)
        assert scene.rects[int(hits.rect[0, 0])].name == "mirror"
        seen[specular] = float(aperture_radiance(scene, hits, table, np.zeros(3))[0, 0])
    # by hand: the eye to the mirror r1, the mirror to the box's face r2 (0.95 m in z)
    r1 = 2.0 / np.cos(np.radians(yaw))
    r2 = 0.95 / np.cos(np.radians(yaw))
    l_amb, l_hot, l_mirror = table.to_radiance(np.array([293.15, 353.15, 293.15]))
    tau1, tau2 = atmospheric_transmission(np.array([r1, r2]), 293.15, 0.5)
    box_leaves = tau2 * (0.95 * l_hot + 0.05 * l_amb) + (1 - tau2) * l_amb
    expected = tau1 * (0.1 * l_mirror + 0.9 * box_leaves) + (1 - tau1) * l_amb
    assert seen[True] == pytest.approx(expected, rel=1e-9)
    assert seen[False] == pytest.approx(l_amb, rel=1e-9)  # a diffuse one: the room
    assert table.to_kelvin(seen[True]) - K > 70.0  # it reads hot


def test_bolometer_memory_keeps_the_mean_and_the_mean_lag() -> None:
    lags, weights = bolometer_memory(0.012)
    assert weights.sum() == pytest.approx(1.0, abs=1e-12)
    assert lags @ weights == pytest.approx(0.012, abs=1e-12)  # the kernel's mean lag: tau
    assert lags.max() >= 3 * 0.012  # reaches past three time constants


def _edge_width_px(row: np.ndarray) -> int:
    """Pixels of a row between 10 and 90 % of its rise."""
    lo, hi = row.min(), row.max()
    return int(np.sum((row > lo + 0.1 * (hi - lo)) & (row < lo + 0.9 * (hi - lo))))


def test_a_moving_rig_smears_the_thermal_image_a_held_one_does_not() -> None:
    scene = occlusion_scene(box_temp_c=80.0)
    still = camera_pose(0.8)
    turning = Rig(
        scene,
        still,
        thermal_time_constant_s=0.012,
        trajectory=lambda t: camera_pose(0.8, yaw_deg=120.0 * t),  # a quick turn
    )
    held = Rig(scene, still, thermal_time_constant_s=0.012, trajectory=lambda t: still)
    sharp = Rig(scene, still)
    np.testing.assert_array_equal(held.aperture_at(1.0), sharp.aperture)  # held: one render
    moving = turning.aperture_at(0.0)
    instant = replace(turning, thermal_time_constant_s=None).aperture_at(0.0)
    row = moving.shape[0] // 2
    # 120 deg/s over the mean lag of 12 ms is 2.5 thermal pixels
    assert _edge_width_px(moving[row]) >= _edge_width_px(instant[row]) + 2
    assert _edge_width_px(instant[row]) == _edge_width_px(sharp.aperture[row])


# -- the walk ----------------------------------------------------------------------------------


@pytest.mark.parametrize(("scene", "pace"), [("machine", (0.35, 0.5)), ("room", (0.25, 0.4))])
def test_a_walk_closes_its_loop_at_a_walking_pace(scene: str, pace: tuple[float, float]) -> None:
    path = walkaround_path(scene, seed=1)
    times = np.linspace(path.start_s, path.end_s, round(path.duration_s * 100) + 1)
    _, truth = walkaround_trajectory(scene, seed=1, times_s=times)
    np.testing.assert_allclose(truth.translations_m[-1], truth.translations_m[0], atol=1e-9)
    np.testing.assert_allclose(truth.rotations[-1], truth.rotations[0], atol=1e-9)
    assert path.laps == 1
    speed = path.speed_m_s(times)
    assert pace[0] <= speed.mean() <= pace[1]  # m/s, start and stop included
    step = np.linalg.norm(np.diff(truth.translations_m, axis=0), axis=1)
    assert step.max() / 0.01 < 0.7  # no jumps: under 0.7 m/s with the bob
    turn = truth.angular_speed_deg_s(times[5:-5])
    assert np.percentile(turn, 90) < 60.0  # mostly under 60 deg/s ...
    assert turn.max() > 90.0  # ... with a few quick glances


def test_the_machine_walk_comes_within_80_cm_of_the_hot_terminal() -> None:
    _, truth = walkaround_trajectory("machine")
    terminal = np.array(part_hotspot(machine_scene(), "terminal").center_m)
    assert np.linalg.norm(truth.translations_m - terminal, axis=1).min() < 0.8


def _weakest_direction(scene: Scene, pose: RigidTransform, intr: Intrinsics) -> float:
    """How well a depth view fixes the camera's pose: the smallest eigenvalue of the
    point-to-plane information sum [p x n, n][p x n, n]^T over its points (camera frame, m)
    over the largest. A plane leaves 3 of the 6 degrees of freedom free (0); a corner or a
    box fixes them all."""
    hits = cast(scene, pose.inverse(), intr)
    ok = hits.rect >= 0
    xs = (np.arange(intr.width) - intr.cx) / intr.fx
    ys = (np.arange(intr.height) - intr.cy) / intr.fy
    rays = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None], 1.0), axis=-1)
    points = (rays * hits.z_m[..., None])[ok]
    normals = scene.geometry.normal[hits.rect[ok]] @ pose.rotation  # world to camera
    j = np.concatenate([np.cross(points, normals), normals], axis=1)
    eig = np.linalg.eigvalsh(j.T @ j)
    return float(eig[0] / eig[-1])


_D435_COARSE = Intrinsics(96, 54, 48.375, 48.375, 47.5, 26.5)  # the D435's 87 x 58 deg FOV


@pytest.mark.parametrize("seed", [0, 1])
def test_every_view_of_the_room_walk_fixes_the_depth_cameras_pose(seed: int) -> None:
    # every half second, glances included: a corner or furniture in view, never a bare
    # wall (a walk 0.5 m from the bare walls of an empty room scores 0 in a third of its)
    scene, path = room_scene(), walkaround_path("room", seed=seed)
    times = np.arange(path.start_s, path.end_s, 0.5)
    weakest = [_weakest_direction(scene, path.pose_at(t), _D435_COARSE) for t in times]
    assert min(weakest) > 1e-3  # measured 3e-3 (seed 1) and 7e-3 (seed 0)


def test_the_room_walk_sees_every_wall_the_radiator_and_the_window() -> None:
    scene, path = room_scene(), walkaround_path("room")
    seen: set[str] = set()
    for t in np.arange(path.start_s, path.end_s, 0.5):
        hits = cast(scene, path.pose_at(t).inverse(), _D435_COARSE)
        ids, counts = np.unique(hits.rect[hits.rect >= 0], return_counts=True)
        seen |= {scene.rects[i].name for i, n in zip(ids, counts, strict=True) if n >= 20}
    walls = {"floor", "ceiling", "west", "east", "south", "north", "north-east-of-window"}
    assert walls | {"window", "radiator-x", "door", "sideboard+x", "computer-x", "lamp+y"} <= seen
    _, pos = path.poses(np.linspace(path.start_s, path.end_s, 2001))
    window = np.array(part_hotspot(scene, "window").center_m)
    assert np.linalg.norm(pos - window, axis=1).min() < 1.3  # measured 1.20 m
    assert np.abs(pos[:, [0, 2]]).max() < 1.2  # 0.8 m or more from the walls (0.84)


def test_the_faces_the_room_leaves_out_are_never_seen(monkeypatch: pytest.MonkeyPatch) -> None:
    # the room's boxes leave out the faces against a wall, the floor or another part: the
    # depth is the same as with every face, from the walk and from eyes anywhere in the room
    from thermodepth.sim import walkaround

    culled = room_scene()
    block = walkaround._block

    def every_face(*args: Any) -> list[Rect]:
        return block(*args[:5])  # all but ``hidden``

    monkeypatch.setattr(walkaround, "_block", every_face)
    full = room_scene()
    assert len(full.rects) > len(culled.rects) + 50
    path = walkaround_path("room")
    rng = np.random.default_rng(0)
    poses = [path.pose_at(t).inverse() for t in np.arange(path.start_s, path.end_s, 1.0)]
    for _ in range(40):  # eyes 0.1-2.35 m up clear of the furniture, looking anywhere
        eye = rng.uniform([-1.2, -2.35, -1.2], [1.2, -0.1, 1.2])
        yaw, pitch = rng.uniform(-180, 180), rng.uniform(-89, 89)
        poses.append(camera_pose(0.0, yaw_deg=yaw, pitch_deg=pitch, target_m=eye).inverse())
    for pose in poses:
        z_culled = cast(culled, pose, _D435_COARSE).z_m
        np.testing.assert_allclose(z_culled, cast(full, pose, _D435_COARSE).z_m, atol=1e-9)


def test_the_rooms_window_mirrors_the_radiator_from_the_left() -> None:
    scene, path = room_scene(), walkaround_path("room")
    times = np.linspace(path.start_s, path.end_s, 4001)
    _, pos = path.poses(times)
    t = times[np.argmin(np.linalg.norm(pos - [-0.5, -1.4, 1.0], axis=1))]  # the waypoint
    cal = walk_rig(WalkConfig.of("room"))[0].calibration
    thermal_from_world = cal.thermal_from_depth @ path.pose_at(t).inverse()
    hits = cast(scene, thermal_from_world, cal.thermal)
    eye = thermal_from_world.inverse().translation_m
    table = radiance_table()
    glass = hits.rect == scene.index("window")
    seen_k = table.to_kelvin(aperture_radiance(scene, hits, table, eye))[glass]
    # the glass alone: 10 C at 0.84 reflecting the 21 C room, near 12 C
    assert np.median(seen_k) - K < 14.0
    assert seen_k.max() - K > 17.0  # the radiator's image: +7 K (measured)


def test_a_short_walk_goes_out_and_back_at_a_pace() -> None:
    path = walkaround_path("machine", 2.0)
    times = np.linspace(path.start_s, path.end_s, 201)
    rot, pos = path.poses(times)
    assert path.laps == 0  # too short to go round
    np.testing.assert_allclose(pos[-1], pos[0], atol=1e-12)
    np.testing.assert_allclose(rot[-1], rot[0], atol=1e-12)
    assert 0.3 <= path.speed_m_s(times).max() <= 0.45


def test_a_30_s_walk_has_ffcs_beyond_the_power_on_one() -> None:
    rig, path = walk_rig(WalkConfig.of("machine"))
    flat = np.full(rig.calibration.thermal.shape, 0.0)
    n = rig.stream_counts(path.duration_s)[1]  # the thermal frames of the walk
    assert n == 262
    states = [rig.sensor.read(rig.thermal_time_s(k), flat)[1].ffc_state for k in range(n)]
    shut = np.array([s == FfcState.IN_PROGRESS for s in states])
    assert not shut[0]  # the walk starts after the power-on FFC
    assert np.sum(np.diff(shut.astype(int)) == 1) >= 1  # at 15.25 s (and 30.5 s)


# -- the recording and its truth ---------------------------------------------------------------


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 1 s walk round the machine at 640x480 with an FFC in it."""
    out = tmp_path_factory.mktemp("walk") / "walk.zarr"
    config = replace(WalkConfig.of("machine", 1.0, 3, depth="640x480"), ffc_interval_s=0.4)
    return simulate_walkaround(out, config=config)


def test_the_walk_records_every_frame_of_both_cameras(walk: Path) -> None:
    rec = Recording(walk)
    assert rec.settings["source"] == "sim:walkaround"
    assert rec.settings["walkaround"]["scene"] == "machine"
    frames = list(rec.frames())
    depth_t = np.array([f.time_s for f in frames if isinstance(f, DepthFrame)])
    thermal = [f for f in frames if isinstance(f, ThermalFrame)]
    thermal_t = np.array([f.time_s for f in thermal])
    assert rec.n_depth == 30 and rec.n_thermal == 9  # 1 s at 30 and 8.7 fps
    np.testing.assert_allclose(np.diff(depth_t), 1 / 30, atol=1e-9)
    np.testing.assert_allclose(np.diff(thermal_t), 1 / 8.7, atol=1e-9)
    assert any(f.telemetry.ffc_state == FfcState.IN_PROGRESS for f in thermal)
    pairs = list(rec.pairs())
    assert [p.index for p in pairs] == list(range(9))
    skew = np.array([p.depth_time_s - p.thermal_time_s for p in pairs])
    assert np.all(np.abs(skew) <= 0.5 / 30 + 1e-9)  # the nearest depth frame


def test_the_walk_carries_its_truth(walk: Path) -> None:
    truth = read_walk_truth(walk)
    assert truth is not None and truth.scene == "machine"
    scene = machine_scene()
    n = len(scene.rects)
    assert truth.rect_names == tuple(r.name for r in scene.rects)
    assert truth.vertices_m.shape == (4 * n, 3) and truth.faces.shape == (2 * n, 3)
    np.testing.assert_array_equal(truth.face_temp_k, np.repeat(truth.temp_k, 2))
    rec = Recording(walk)
    depth_t = [rec.depth_frame(i).time_s for i in range(rec.n_depth)]
    np.testing.assert_allclose(truth.trajectory.times_s, depth_t, atol=1e-12)
    pose = walkaround_path("machine", 1.0, 3).pose_at(depth_t[10])
    np.testing.assert_allclose(truth.trajectory.pose(10).translation_m, pose.translation_m)
    assert {h.name for h in truth.hotspots} >= {"terminal", "bearing-a", "motor"}
    terminal = next(h for h in truth.hotspots if h.name == "terminal")
    assert terminal.temp_c == pytest.approx(80.0) and max(terminal.size_m) == pytest.approx(0.03)
    assert truth.ambient_temp_k == pytest.approx(22.0 + K)
    points, _, which = truth.seen_samples()
    assert truth.seen_depth.shape == truth.seen_thermal.shape == (len(points),)
    assert truth.seen_step == 3 and truth.seen_spacing_m == 0.02
    # 10 depth views of 30 frames; thermal ones out of FFC: fewer, in a narrower view
    assert truth.seen_depth.max() <= 10 and truth.seen_depth.sum() > truth.seen_thermal.sum()
    hidden = which == scene.index("skid+y")  # the skid's underside, on the floor
    assert truth.seen_depth[hidden].max() == 0
    assert (truth.seen_depth[which == scene.index("terminal")] > 0).all()  # seen from the start
    dist, t_k, _ = truth.nearest(points[::50])
    np.testing.assert_allclose(dist, 0.0, atol=1e-12)
    np.testing.assert_array_equal(np.isin(t_k, truth.temp_k), True)


def test_a_recording_without_a_walk_has_no_truth(tmp_path: Path) -> None:
    from thermodepth.io.recording import RecordingWriter

    with RecordingWriter(tmp_path / "r.zarr") as writer:
        writer.add_pair(Rig(plate_scene(), camera_pose(1.0)).frame())
    assert read_walk_truth(tmp_path / "r.zarr") is None


def test_nearest_is_the_exact_distance_to_a_rect() -> None:
    # a 1 m square in z = 0 and a 2 x 1 m one in x = 3 (its normal along x)
    rects = RectArrays(
        np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]]),
        np.array([EX, EZ]),
        np.array([EY, EY]),
        np.array([EZ, np.cross(EZ, EY)]),
        np.array([[0.5, 0.5], [1.0, 0.5]]),
    )
    points = np.array(
        [
            [0.2, 0.1, 0.3],  # above the face: 0.3
            [-1.5, 0.0, 0.0],  # beside an edge: 1.0
            [-1.5, 1.5, 1.0],  # off a corner: sqrt(3)
            [0.1, -0.2, 0.0],  # on it: 0
            [3.4, 0.0, 0.5],  # in front of the second one: 0.4
            [2.0, 0.0, 0.0],  # 1.5 from the first, 1 from the second
        ]
    )
    dist, which = nearest_rect(rects, points)
    np.testing.assert_allclose(dist, [0.3, 1.0, np.sqrt(3), 0.0, 0.4, 1.0], atol=1e-12)
    np.testing.assert_array_equal(which, [0, 0, 0, 0, 1, 1])


def test_nearest_in_blocks_agrees_with_one_brute_force_pass() -> None:
    geometry = machine_scene().geometry
    rng = np.random.default_rng(0)
    points = rng.uniform([-3, -3, -3], [3, 0, 3], (20_000, 3))  # more than one block
    dist, which = nearest_rect(geometry, points)
    samples, _ = surface_samples(geometry, 0.05)
    # the nearest sample is never nearer than the nearest rect, nor further than a cell
    sub = points[:80]
    d2 = ((sub[:, None] - samples[None]) ** 2).sum(axis=2)
    nearest_sample = np.sqrt(d2.min(axis=1))
    assert np.all(dist[:80] <= nearest_sample + 1e-12)
    assert np.all(nearest_sample - dist[:80] <= 0.05 * np.sqrt(2) / 2 + 1e-9)
    assert which.min() >= 0 and which.max() < len(geometry.center_m)


# -- the command ---------------------------------------------------------------------------


def test_simulate_walkaround_writes_a_recording(tmp_path: Path) -> None:
    out = tmp_path / "room.zarr"
    args = ["simulate", "walkaround", "-o", str(out), "--scene", "room", "--duration-s", "0.3"]
    result = runner.invoke(app, [*args, "--depth-mode", "640x480"])
    assert result.exit_code == 0, result.output
    assert f"wrote {out}" in result.output.replace("\n", "")  # a long path is folded
    rec = Recording(out)
    assert rec.n_depth == 9 and rec.n_thermal == 3 and rec.calibration is not None
    truth = read_walk_truth(out)
    assert truth is not None and truth.scene == "room"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--scene", "garden"], "--scene: unknown 'garden'; choose from machine, room"),
        (["--duration-s", "0"], "--duration: must be > 0 seconds"),
        (["--thermal-camera", "x"], "--thermal-camera: unknown 'x'; choose from"),
        (["--depth-mode", "100x100"], "--depth-mode: '100x100': the simulated D435 offers"),
    ],
)
def test_bad_walkaround_options_are_one_line(tmp_path: Path, args: list[str], message: str) -> None:
    out = tmp_path / "w.zarr"
    result = runner.invoke(app, ["simulate", "walkaround", "-o", str(out), *args])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {message}"), result.output
    assert not out.exists()


def test_the_walk_rig_is_placed_as_its_world_from_depth() -> None:
    pose_at, _ = walkaround_trajectory("room", 2.0)
    pose = pose_at(1.5)
    assert isinstance(pose, RigidTransform) and pose.name == "world_from_depth"
