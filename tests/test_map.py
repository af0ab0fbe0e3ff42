"""The 3D thermal map's parts: the TSDF and its mesh against known geometry, the fusion's
weights and robust reduction against samples built by hand, the model's files read back by
independent readers (trimesh, pygltflib), a bag's /tf as the trajectory, and the
hotspots located on a mesh."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

pytest.importorskip("skimage", reason="the map needs the map extra (scikit-image)")

from thermodepth.calibration import Calibration
from thermodepth.camera import Intrinsics, RigidTransform, pixel_rays
from thermodepth.mapping.fusion import (
    FusionOptions,
    SurfaceTemperature,
    ThermalView,
    edge_distance_px,
    fuse,
    render_z,
    smear_px,
    view_weight,
)
from thermodepth.mapping.metrics import world_alignment
from thermodepth.mapping.model import ThermalModel
from thermodepth.mapping.volume import Volume, lens_for
from thermodepth.radiometry import ZERO_C_IN_K, band_radiance, fresnel_emissivity
from thermodepth.sim.scene import camera_pose
from thermodepth.trajectory import Trajectory, rigid_alignment

THERMAL = Intrinsics(160, 120, 150.0, 150.0, 79.5, 59.5, np.zeros(5))


def _plane_depth(intr: Intrinsics, z_m: float) -> np.ndarray:
    return np.full(intr.shape, z_m, np.float32)


def test_a_plane_seen_from_three_poses_meshes_where_it_is_facing_the_cameras() -> None:
    # a wall at z = 1 m in the world, seen head-on and turned by 10 degrees each way
    intr = Intrinsics(160, 120, 120.0, 120.0, 79.5, 59.5, np.zeros(5))
    rays = pixel_rays(intr)
    volume = Volume.of_bounds(np.array([-0.4, -0.3, 0.9]), np.array([0.4, 0.3, 1.1]), 0.01)
    for yaw in (-10.0, 0.0, 10.0):
        pose = camera_pose(1.0, yaw_deg=yaw, target_m=(0.0, 0.0, 1.0))
        # the depth of a plane z = 1 (world) along each pixel's ray, seen from the pose
        d = pose.rotation @ np.stack([rays[0], rays[1], np.ones_like(rays[0])], -1)[..., None]
        depth = ((1.0 - pose.translation_m[2]) / d[..., 2, 0]).astype(np.float32)
        volume.integrate(depth, intr, pose, rays, stride=2)
    verts, faces, normals = volume.mesh()
    assert len(faces) > 1000
    inner = (np.abs(verts[:, 0]) < 0.25) & (np.abs(verts[:, 1]) < 0.2)
    assert np.abs(verts[inner, 2] - 1.0).max() < 0.002  # 2 mm at 1 cm voxels, noise-free
    assert np.all(normals[inner, 2] < -0.99)  # out of the surface, towards the cameras
    a, b, c = (verts[faces[:, k]] for k in range(3))
    winding = np.einsum("ij,ij->i", np.cross(b - a, c - a), normals[faces].mean(1))
    assert np.mean(winding > 0) > 0.97  # triangles wound as their normals point


def test_a_grid_turns_to_a_tilted_world_and_meshes_back_into_it() -> None:
    # the plane z = 1 of the test above in a world turned 35 degrees about x and 20 about y
    # (odometry's world is its first camera, tilted): the grid turns with the plane, so
    # it is a fraction of the axis-aligned box, and the mesh comes back into the world
    intr = Intrinsics(160, 120, 120.0, 120.0, 79.5, 59.5, np.zeros(5))
    rays = pixel_rays(intr)
    turn = RigidTransform(
        Rotation.from_euler("xy", [35, 20], degrees=True).as_matrix(), np.zeros(3), "world",
        "world",
    )  # fmt: skip
    ray = np.stack([rays[0], rays[1], np.ones_like(rays[0])], -1)
    frames = []
    for yaw in (-10.0, 0.0, 10.0):
        pose = camera_pose(1.0, yaw_deg=yaw, target_m=(0.0, 0.0, 1.0))
        d = ray @ pose.rotation.T
        depth = ((1.0 - pose.translation_m[2]) / d[..., 2]).astype(np.float32)
        frames.append((depth, turn @ pose))
    points = np.concatenate([p.apply(ray * z[..., None]).reshape(-1, 3) for z, p in frames])
    volume = Volume.of_points(points, 0.01)
    lo, hi = points.min(0), points.max(0)
    assert np.prod(volume.shape) < 0.5 * np.prod(np.ceil((hi - lo) / 0.01 + 9))
    for depth, pose in frames:
        volume.integrate(depth, intr, pose, rays, stride=2)
    verts, faces, normals = volume.mesh()
    assert len(faces) > 1000
    local = turn.inverse().apply(verts)  # back to the plane's own world
    inner = (np.abs(local[:, 0]) < 0.25) & (np.abs(local[:, 1]) < 0.2)
    assert np.abs(local[inner, 2] - 1.0).max() < 0.002
    assert np.all((normals[inner] @ turn.rotation)[:, 2] < -0.99)


def test_a_straight_walk_is_aligned_by_its_poses_not_its_positions_alone() -> None:
    # a walk along a straight line, its world turned 30 degrees about that line: positions
    # alone cannot see the turn; whole poses can
    n = 20
    truth = Trajectory(
        np.arange(n) * 0.1,
        Rotation.from_euler("y", np.linspace(-20, 20, n)[:, None], degrees=True).as_matrix(),
        np.stack([np.linspace(0, 0.5, n), np.zeros(n), np.zeros(n)], -1),
    )
    turn = Rotation.from_euler("x", 30, degrees=True).as_matrix()
    shift = np.array([0.2, -0.1, 0.3])
    estimate = Trajectory(
        truth.times_s, turn.T @ truth.rotations, (truth.translations_m - shift) @ turn
    )  # the truth's world = turn @ the estimate's + shift
    align = world_alignment(estimate, truth)
    np.testing.assert_allclose(align.rotation, turn, atol=1e-9)
    np.testing.assert_allclose(align.translation_m, shift, atol=1e-9)
    by_positions, _ = rigid_alignment(estimate.translations_m, truth.translations_m)
    assert Rotation.from_matrix(by_positions.T @ turn).magnitude() > np.radians(10)


def test_a_volume_too_large_is_one_line_naming_its_size() -> None:
    with pytest.raises(ValueError, match=r"M voxels .* larger voxel or a shorter max range"):
        Volume.of_bounds(np.zeros(3), np.full(3, 20.0), 0.005)


def test_view_weights_follow_the_shutter_and_the_smear() -> None:
    o = FusionOptions()
    assert view_weight(True, 0.0, o) == 0.0
    assert view_weight(False, 0.3, o) == 1.0
    assert view_weight(False, 2.5, o) == 0.0
    assert view_weight(False, 1.25, o) == pytest.approx(0.5)
    # 60 deg/s for 12 ms at 150 px/rad: 1.885 px
    assert smear_px(60.0, 150.0, 0.012) == pytest.approx(np.radians(60) * 0.012 * 150)


def test_edge_distance_counts_pixels_from_a_depth_step() -> None:
    z = np.full((40, 60), 2.0, np.float32)
    z[:, 30:] = 1.0  # a step at column 30
    d = edge_distance_px(z, 0.01)
    assert d[20, 29] == 0 and d[20, 30] == 0
    assert d[20, 25] == pytest.approx(4.0, abs=0.5)
    assert d[20, 40] == pytest.approx(10.0, abs=0.5)


def _flat_views(
    temps_c: list[float], yaws_deg: list[float], dist_m: float = 1.0
) -> tuple[np.ndarray, np.ndarray, list[ThermalView]]:
    """A 1 x 1 m plane at z = 0 facing -z, a vertex every 2 cm, and a view per (temperature,
    yaw): the view reads the one temperature everywhere."""
    g = np.arange(-0.2, 0.2001, 0.02)
    xs, ys = np.meshgrid(g, g)
    verts = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], -1)
    normals = np.tile([0.0, 0.0, -1.0], (len(verts), 1))
    views = []
    for k, (t_c, yaw) in enumerate(zip(temps_c, yaws_deg, strict=True)):
        pose = camera_pose(dist_m, yaw_deg=yaw).inverse()
        thermal_from_world = RigidTransform(pose.rotation, pose.translation_m, "thermal", "world")
        z = render_z(verts.astype(np.float32), [thermal_from_world], lens_for(THERMAL), 0.02)[0]
        temp = np.full(THERMAL.shape, t_c, np.float32)
        edge = np.full(THERMAL.shape, 10.0, np.float32)
        views.append(ThermalView(float(k), thermal_from_world, temp, z, edge, 1.0, 0.0))
    return verts, normals, views


def _fused(
    views: list[ThermalView], verts: np.ndarray, normals: np.ndarray, **kw: object
) -> SurfaceTemperature:
    opts = FusionOptions(directional=False, **kw)  # type: ignore[arg-type]
    return fuse(verts, normals, views, THERMAL, 0.02, 0.95, 25.0, opts)


def test_the_median_sets_a_reflection_aside_that_the_plain_mean_takes() -> None:
    temps = [40.0, 40.1, 39.9, 40.0, 48.0]  # the last view sees a reflection
    verts, normals, views = _flat_views(temps, [0, 5, -5, 10, -10])
    s = _fused(views, verts, normals)
    assert np.all(s.views == 5)
    np.testing.assert_allclose(s.temp_c, 40.0, atol=1e-4)  # the weighted median
    np.testing.assert_allclose(s.plain_c, np.mean(temps), atol=1e-4)
    assert np.all(s.spread_c < 0.2)
    trimmed = _fused(views, verts, normals, method="trimmed")
    assert np.all(np.abs(trimmed.temp_c - 40.0) < 0.1)
    mean = _fused(views, verts, normals, method="mean")
    assert np.all(mean.temp_c > 41.0)  # the weighted mean is pulled by the reflection


def test_grazing_views_are_not_trusted_but_count_in_the_baseline() -> None:
    verts, normals, views = _flat_views([40.0, 30.0], [0.0, 70.0])
    s = _fused(views, verts, normals)
    centre = np.argmin(np.linalg.norm(verts, axis=1))
    assert s.views[centre] == 1 and s.temp_c[centre] == pytest.approx(40.0)
    assert s.plain_c[centre] == pytest.approx(35.0)


def test_the_nearest_view_gives_the_best_temperature_and_counts_most() -> None:
    near = _flat_views([50.0], [0.0], dist_m=0.5)[2]
    verts, normals, far = _flat_views([44.0, 44.0], [5.0, -5.0], dist_m=2.0)
    s = _fused(near + far, verts, normals)
    centre = np.argmin(np.linalg.norm(verts, axis=1))
    assert s.best_c[centre] == pytest.approx(50.0)
    # weight (1 cm / footprint)^2: the near view outweighs both far ones, so it is the median
    assert s.temp_c[centre] == pytest.approx(50.0)
    assert s.last_seen_s[centre] == 1.0  # the far views' times are 0 and 1, the near one's 0


def test_hidden_vertices_take_no_sample() -> None:
    verts, normals, views = _flat_views([40.0], [0.0])
    shade = views[0].z_m.copy()
    shade[:, :80] = 0.5  # something nearer covers the left half of the image
    blocked = ThermalView(
        0.0, views[0].thermal_from_world, views[0].temp_c, shade, views[0].edge_px, 1.0, 0.0
    )
    s = _fused([blocked], verts, normals)
    left = verts[:, 0] < -0.05  # x < 0 projects left of the centre
    assert np.all(s.views[left] == 0) and np.all(s.views[verts[:, 0] > 0.05] == 1)


def test_the_angle_correction_inverts_a_directional_emissivity() -> None:
    # a surface at 40 C of normal emissivity 0.95 seen at 50 deg: a camera that assumes 0.95
    # reads what L = eps(50) L(40) + (1 - eps(50)) L(25) gives at 0.95; the fusion undoes it
    eps_n, t_true, t_refl = 0.95, 40.0, 25.0
    cos = np.cos(np.radians(50.0))
    eps = float(fresnel_emissivity(np.array([cos]), eps_n)[0])
    l_true, l_refl = band_radiance(np.array([t_true, t_refl]) + ZERO_C_IN_K)
    seen = eps * l_true + (1 - eps) * l_refl
    grid = np.linspace(20.0, 60.0, 400001)
    read_c = float(
        np.interp((seen - (1 - eps_n) * l_refl) / eps_n, band_radiance(grid + ZERO_C_IN_K), grid)
    )
    assert read_c < t_true - 0.2  # the uncorrected reading is low
    verts, normals, views = _flat_views([read_c], [50.0])
    views = [
        ThermalView(0.0, v.thermal_from_world, v.temp_c, v.z_m, v.edge_px, 1.0, 0.0) for v in views
    ]
    s = fuse(verts, normals, views, THERMAL, 0.02, eps_n, t_refl, FusionOptions())
    centre = np.argmin(np.linalg.norm(verts, axis=1))
    # the view's angle varies over the plane: the centre's is 50 deg within a degree
    assert s.temp_c[centre] == pytest.approx(t_true, abs=0.1)


def test_hotspots_are_connected_hot_parts_with_their_area_and_peak() -> None:
    g = np.arange(0.0, 0.5001, 0.01)
    xs, ys = np.meshgrid(g, g)
    verts = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], -1)
    n = len(g)
    idx = np.arange(n * n).reshape(n, n)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    temp = np.full(len(verts), 25.0)
    hot = (np.abs(xs - 0.1) < 0.0205) & (np.abs(ys - 0.1) < 0.0205)  # 5 x 5 vertices: 4 x 4 cm
    temp[hot.ravel()] = 70.0
    temp[idx[40, 40]] = 80.0
    temp[idx[40, 41]] = 75.0
    temp[idx[41, 40]] = 75.0
    nan = np.full(len(verts), np.nan)
    surface = SurfaceTemperature(temp, nan, np.ones(len(verts), np.int32), nan, temp, nan, temp)
    normals = np.tile([0.0, 0.0, -1.0], (len(verts), 1))
    model = ThermalModel(verts, faces, normals, surface, 0.01)
    spots = model.hotspots(60.0)
    assert len(spots) == 2 and spots[0].peak_c == 80.0
    np.testing.assert_allclose(spots[0].peak_m, [0.40, 0.40, 0.0])
    big = spots[1]
    # the centre: within a millimetre (the triangles' diagonals make the rim's areas uneven)
    np.testing.assert_allclose(big.centre_m, [0.1, 0.1, 0.0], atol=1e-3)
    # the vertices own a third of their triangles: 4 x 4 cm inside, half cells on the rim
    assert 16e-4 < big.area_m2 < 25e-4
    assert model.hotspots(90.0) == []


def test_model_files_are_read_back_by_independent_readers(tmp_path: Path) -> None:
    trimesh = pytest.importorskip("trimesh", reason="model.glb needs the map extra (trimesh)")
    pygltflib = pytest.importorskip("pygltflib", reason="a second glTF reader (dev extra)")

    from thermodepth.io.model import (
        SCALARS,
        read_model_ply,
        temperature_colours,
        write_model_glb,
        write_model_ply,
    )

    rng = np.random.default_rng(0)
    verts = rng.normal(size=(50, 3))
    faces = rng.integers(0, 50, size=(80, 3))
    normals = verts / np.linalg.norm(verts, axis=1, keepdims=True)
    temp = rng.uniform(20, 80, 50)
    temp[3] = np.nan
    rgb = temperature_colours(temp, (20.0, 80.0), "inferno")
    assert tuple(rgb[3]) == (128, 128, 128)
    scalars = {name: rng.uniform(0, 9, 50).astype(np.float32) for name in SCALARS}
    scalars["temperature"] = temp
    ply = write_model_ply(tmp_path / "m.ply", verts, faces, normals, rgb, scalars)
    mesh = trimesh.load(ply, process=False)  # trimesh's own PLY reader: an independent one
    np.testing.assert_array_equal(mesh.vertices, verts.astype(np.float32))
    np.testing.assert_array_equal(mesh.faces, faces)
    np.testing.assert_array_equal(mesh.visual.vertex_colors[:, :3], rgb)
    raw = mesh.metadata["_ply_raw"]["vertex"]["data"]  # every property as the file has it
    for name in SCALARS:
        np.testing.assert_array_equal(raw[f"scalar_{name}"], scalars[name].astype(np.float32))
    np.testing.assert_array_equal(raw["nz"], normals[:, 2].astype(np.float32))
    back = read_model_ply(ply)
    np.testing.assert_allclose(back["temperature"], temp.astype(np.float32), equal_nan=True)
    np.testing.assert_allclose(back["spread"], scalars["spread"])
    np.testing.assert_array_equal(back["triangles"], faces)
    scale = {"palette": "inferno", "min_c": 20.0, "max_c": 80.0}
    glb = write_model_glb(tmp_path / "m.glb", verts, faces, normals, rgb, temp, scale)
    gltf = pygltflib.GLTF2().load(str(glb))
    prim = gltf.meshes[0].primitives[0]
    assert prim.attributes.COLOR_0 is not None
    acc = gltf.accessors[prim.attributes._TEMPERATURE]
    view = gltf.bufferViews[acc.bufferView]
    blob = gltf.binary_blob()
    start = view.byteOffset + (acc.byteOffset or 0)
    got = np.frombuffer(blob[start : start + 4 * acc.count], np.float32)
    np.testing.assert_allclose(got, temp.astype(np.float32), equal_nan=True)
    assert gltf.scenes[0].extras["temperature_scale"] == scale


def test_a_bags_tf_gives_the_depth_cameras_poses(tmp_path: Path) -> None:
    pytest.importorskip("rosbags", reason="ROS bags need the ros extra (rosbags)")
    from thermodepth.io.ros import FRAMES, TF, BagWriter, tf_msg, write_rig
    from thermodepth.sim import Rig, plate_scene
    from thermodepth.sources import open_source
    from thermodepth.trajectory import Trajectory

    rig = Rig(plate_scene(), camera_pose(1.0), seed=1)
    pairs = list(rig.frames(4))
    # map -> base (moving, on /tf) -> the thermal camera's frame (static) -> the depth
    # camera's (static, as write_rig puts it: the depth frame's pose in the thermal's)
    mount = RigidTransform(np.eye(3), np.array([0.0, -0.2, 0.1]), "base", FRAMES["thermal"])
    thermal_from_depth = rig.calibration.thermal_from_depth
    depth_in_thermal = RigidTransform(
        thermal_from_depth.rotation,
        thermal_from_depth.translation_m,
        FRAMES["thermal"],
        FRAMES["depth"],
    )
    truth = []
    with BagWriter(tmp_path / "walk.mcap", "mcap") as writer:
        for k, pair in enumerate(pairs):
            write_rig(writer, rig.calibration, pair, with_tf=k == 0)
            if k == 0:
                writer.write("/tf_static", TF, tf_msg(writer.store, [mount], 0.0), 0.0, True)
            base = RigidTransform(
                camera_pose(1.0, yaw_deg=5.0 * k).rotation, np.array([0.1 * k, 0, 0]), "map", "base"
            )
            t = pair.depth_time_s
            writer.write("/tf", TF, tf_msg(writer.store, [base], t), t)
            truth.append((t, base @ mount @ depth_in_thermal))
    with open_source(f"rosbag:{tmp_path / 'walk.mcap'}") as src:
        found = src.trajectory()
    assert found is not None
    trajectory, told = found
    assert told.startswith(f"/tf (map -> {FRAMES['depth']}")
    expected = Trajectory.of_poses([t for t, _ in truth], [p for _, p in truth])
    np.testing.assert_allclose(trajectory.times_s, expected.times_s)
    np.testing.assert_allclose(trajectory.rotations, expected.rotations, atol=1e-9)
    np.testing.assert_allclose(trajectory.translations_m, expected.translations_m, atol=1e-9)
    assert isinstance(rig.calibration, Calibration)


def test_the_model_for_rerun_is_read_back_by_reruns_reader(tmp_path: Path) -> None:
    pytest.importorskip("rerun", reason="the viewer needs the viewer extra (rerun-sdk)")
    from rerun.chunk import RrdReader

    from thermodepth.sinks.viewer import save_model
    from thermodepth.trajectory import Trajectory

    rng = np.random.default_rng(1)
    verts = rng.normal(size=(40, 3))
    faces = rng.integers(0, 40, size=(25, 3))
    normals = verts / np.linalg.norm(verts, axis=1, keepdims=True)
    rgb = rng.integers(0, 255, size=(40, 3)).astype(np.uint8)
    path = Trajectory.of_poses([0.0, 1.0], [camera_pose(1.0), camera_pose(1.0, yaw_deg=10.0)])
    rrd = save_model(tmp_path / "m.rrd", verts, faces, normals, rgb, path, [verts[0]])
    reader = RrdReader(str(rrd))
    assert {"/world/model", "/world/trajectory", "/world/hotspots"} <= set(
        reader.store().schema().entity_paths()
    )
    chunks = list(reader.stream().filter(content="/world/model", is_static=True))
    batch = chunks[0].to_record_batch()
    got = np.array(batch.column("Mesh3D:vertex_positions").to_pylist()[0])
    np.testing.assert_allclose(got, verts.astype(np.float32), rtol=1e-6)
    tri = np.array(batch.column("Mesh3D:triangle_indices").to_pylist()[0])
    np.testing.assert_array_equal(tri, faces)
