"""The simulator's shading kernels against their numpy definitions, bit for bit: the material
each ray meets (patterns), the aperture radiance (Fresnel emissivity, one specular bounce, the
air), the pixel footprint, and the one-pass renders."""

from __future__ import annotations

import numpy as np
import pytest

from thermodepth.board import BoardSpec
from thermodepth.calibration import Calibration
from thermodepth.camera import Intrinsics, RigidTransform, rotation_from_euler
from thermodepth.radiometry import atmospheric_transmission, fresnel_emissivity
from thermodepth.sim import camera_pose, default_calibration, plate_scene
from thermodepth.sim.lepton import RadianceTable, radiance_table
from thermodepth.sim.raycast import Hits, RayHits, cast, cast_rays
from thermodepth.sim.scene import Material, Rect, Scene, board_pattern, box, target_scene
from thermodepth.sim.shading import (
    SurfaceHits,
    aperture_radiance,
    footprint_and_blur,
    near_ir_albedo,
    render_aperture,
    render_ir_albedo,
    surface_properties,
)
from thermodepth.sim.walkaround import machine_scene, room_scene

FloatArray = np.typing.NDArray[np.float64]

CAL: Calibration = default_calibration()
CHECKER = BoardSpec.parse("checkerboard:9x6", 0.03)
CIRCLES = BoardSpec.parse("circles:4x11", 0.02)


# -- the numpy definitions ---------------------------------------------------------------------


def _property(scene: Scene, hits: SurfaceHits, name: str, missed: float) -> FloatArray:
    """A material property per ray: the rect's, its pattern's second material's where
    ``second_material`` puts it, ``missed`` where nothing is hit."""
    n = len(scene.rects)
    values = [float(getattr(r.material, name)) for r in scene.rects]
    out = np.asarray([*values, missed])[np.where(hits.rect >= 0, hits.rect, n)]
    for i, rect in enumerate(scene.rects):
        if rect.pattern is None or rect.material_b is None:
            continue
        on = np.flatnonzero(hits.rect.ravel() == i)
        second = rect.pattern.second_material(hits.s_m.ravel()[on], hits.q_m.ravel()[on])
        out.ravel()[on[second]] = float(getattr(rect.material_b, name))
    return out


def _radiance(
    scene: Scene,
    hits: SurfaceHits,
    range_m: FloatArray,
    table: RadianceTable,
    eye_m: FloatArray | None = None,
    directions: FloatArray | None = None,
) -> FloatArray:
    """L_ap = tau(r) [eps L(T) + (1 - eps) L_r] + (1 - tau(r)) L(T_amb) over whole arrays:
    eps Fresnel's at the angle of view for directional materials, L_r what the mirrored ray
    meets for specular ones seen from the eye, else the ambient's."""
    temp = _property(scene, hits, "temp_k", scene.ambient_temp_k)
    emis = _property(scene, hits, "emissivity", 1.0)
    l_amb = float(table.to_radiance(scene.ambient_temp_k))
    l_refl = np.full(emis.shape, l_amb)
    g, rect, dist = scene.geometry, hits.rect.ravel(), range_m.ravel()
    turn = np.flatnonzero(_property(scene, hits, "directional", 0.0).ravel() > 0)
    if eye_m is not None:
        plane_m = np.abs(np.einsum("ij,ij->i", g.normal, g.center_m - eye_m))
        cos = plane_m[rect[turn]] / dist[turn]
    else:
        assert directions is not None
        cos = np.einsum("ij,ij->i", directions.reshape(-1, 3)[turn], g.normal[rect[turn]])
    emis.ravel()[turn] = fresnel_emissivity(cos, emis.ravel()[turn])
    mirror = np.flatnonzero(_property(scene, hits, "specular", 0.0).ravel() > 0)
    if eye_m is not None and mirror.size:
        on = rect[mirror]
        points = g.points_m(on, hits.s_m.ravel()[mirror], hits.q_m.ravel()[mirror])
        view = points - eye_m
        view /= np.linalg.norm(view, axis=1, keepdims=True)
        normal = g.normal[on]
        out = view - 2.0 * np.einsum("ij,ij->i", view, normal)[:, None] * normal
        seen = cast_rays(scene, points, out, skip=on)
        l_refl.ravel()[mirror] = _radiance(scene, seen, seen.t, table, directions=out)
    tau = atmospheric_transmission(
        np.where(hits.rect >= 0, range_m, 0.0), scene.ambient_temp_k, scene.relative_humidity
    )
    return tau * (emis * table.to_radiance(temp) + (1.0 - emis) * l_refl) + (1.0 - tau) * l_amb


# -- scenes that use every path: patterns, directional surfaces, mirrors ------------------------


def _board(board: BoardSpec, style: str) -> tuple[Scene, RigidTransform]:
    return target_scene(board_pattern(board), style=style), camera_pose(0.45, 15, -10, 5)


def _tilted() -> Scene:
    """A glossy tilted mirror facing a hot box turned on every axis and a wall behind the
    eye, a tilted checkerboard beside them (nothing lines up with an axis: every dot product
    has three terms)."""
    turn = rotation_from_euler(0.3, -0.5, 0.7)
    glass = Material(290.0, 0.84, 0.1, "glass", directional=True, specular=True)
    paint = Material(340.0, 0.9, 0.4, "paint", directional=True)
    cold = Material(285.0, 0.95, 0.6, "cold", directional=True)
    tilt = rotation_from_euler(0.1, 0.15, 0.2)
    rects = [
        Rect(np.array([0.1, 0.0, 1.2]), tilt[:, 0], tilt[:, 1], 0.4, 0.3, glass, name="mirror"),
        Rect(
            np.array([-0.3, 0.1, 0.9]),
            turn[:, 1],
            turn[:, 2],
            0.1,
            0.12,
            Material(300.0, 0.1, 0.8, "metal", directional=True),
            board_pattern(CHECKER),
            cold,
            name="board",
        ),
    ]
    rects += box([0.3, -0.1, 0.5], (0.12, 0.1, 0.08), paint, turn.T, name="hot")
    behind = rotation_from_euler(-0.2, 0.25, 0.15)  # a wall behind the eye, in the mirror
    rects.append(Rect(np.array([0.0, 0.0, -1.5]), behind[:, 0], behind[:, 1], 4.0, 4.0, cold))
    return Scene(tuple(rects), 295.0, 0.4)


VIEWS = {
    "plate": (plate_scene(chip_temp_c=70.0), camera_pose(0.6, 10, 5)),
    "checkerboard": _board(CHECKER, "bare"),
    "circles": _board(CIRCLES, "mask"),
    # the stainless guard (a mirror) behind the motor, from behind it and to the right
    "machine": (machine_scene(), camera_pose(1.2, -160, 0, 0, (0.45, -0.45, 0.3))),
    # the window (a mirror) in its reveal, from the room
    "room": (room_scene(), camera_pose(1.2, 0, 20, 0, (0.75, -0.95, 2.15))),
    "tilted": (_tilted(), camera_pose(1.0, -10, 5, 3, (0.0, 0.0, 1.0))),
}


def _thermal_view(name: str) -> tuple[Scene, RigidTransform, FloatArray]:
    """A scene, thermal_from_world looking at it, and the eye (world)."""
    scene, pose = VIEWS[name]
    thermal_from_world = CAL.thermal_from_depth @ pose.inverse()
    return scene, thermal_from_world, thermal_from_world.inverse().translation_m


def _specular_hits(scene: Scene, hits: Hits) -> int:
    specular = [i for i, r in enumerate(scene.rects) if r.material.specular]
    return int(np.isin(hits.rect, specular).sum())


@pytest.mark.parametrize("name", list(VIEWS))
def test_aperture_radiance_is_its_numpy_definition_bit_for_bit(name: str) -> None:
    scene, thermal_from_world, eye = _thermal_view(name)
    hits = cast(scene, thermal_from_world, CAL.thermal, 2)
    table = radiance_table()
    if name in ("machine", "room", "tilted"):  # they hold mirrors and directional surfaces
        assert scene.has_optics and _specular_hits(scene, hits) > 500
    expected = _radiance(scene, hits, hits.range_m, table, eye_m=eye)
    np.testing.assert_array_equal(aperture_radiance(scene, hits, table, eye), expected)


@pytest.mark.parametrize("name", list(VIEWS))
def test_material_properties_follow_the_patterns(name: str) -> None:
    scene, pose = VIEWS[name]
    hits = cast(scene, pose.inverse(), Intrinsics(160, 90, 80.0, 80.0, 79.5, 44.5), 3)
    temp, emis, albedo = surface_properties(scene, hits)
    np.testing.assert_array_equal(temp, _property(scene, hits, "temp_k", scene.ambient_temp_k))
    np.testing.assert_array_equal(emis, _property(scene, hits, "emissivity", 1.0))
    np.testing.assert_array_equal(albedo, _property(scene, hits, "ir_albedo", 0.0))
    np.testing.assert_array_equal(near_ir_albedo(scene, hits), albedo)
    if name in ("checkerboard", "circles"):  # both materials of the board are seen
        on_board = hits.rect == scene.index("board")
        assert len(np.unique(albedo[on_board])) == 2


def test_materials_of_arbitrary_rays_follow_the_patterns() -> None:
    scene = VIEWS["circles"][0]
    rng = np.random.default_rng(3)
    n = 20_000
    rect = rng.integers(-1, 2, n)  # the board, the wall, nothing
    s, q = rng.uniform(-0.12, 0.12, n), rng.uniform(-0.12, 0.12, n)
    hits = RayHits(np.ones(n), rect, np.where(rect >= 0, s, np.nan), np.where(rect >= 0, q, np.nan))
    np.testing.assert_array_equal(
        surface_properties(scene, hits)[2], _property(scene, hits, "ir_albedo", 0.0)
    )


@pytest.mark.parametrize("ss", [1, 2, 3, 5, 8, 13, 16])
def test_the_footprint_is_numpys_mean_bit_for_bit(ss: int) -> None:
    rng = np.random.default_rng(ss)
    sub = rng.standard_normal((12 * ss, 20 * ss)) * 1e3 + rng.uniform(0, 1e-6, (12 * ss, 20 * ss))
    mean = sub.reshape(12, ss, 20, ss).mean(axis=(1, 3))
    np.testing.assert_array_equal(footprint_and_blur(sub, ss, 0.0), mean)


@pytest.mark.parametrize(("name", "ss"), [(n, 3) for n in VIEWS] + [("room", 4), ("plate", 8)])
def test_a_render_is_the_mean_of_its_sub_rays_bit_for_bit(name: str, ss: int) -> None:
    scene, thermal_from_world, eye = _thermal_view(name)
    table = radiance_table()
    sub = aperture_radiance(scene, cast(scene, thermal_from_world, CAL.thermal, ss), table, eye)
    np.testing.assert_array_equal(
        render_aperture(scene, thermal_from_world, CAL.thermal, ss, 0.6, table),
        footprint_and_blur(sub, ss, 0.6),
    )
    depth_from_world = VIEWS[name][1].inverse()
    depth = Intrinsics(320, 180, 161.25, 161.25, 159.5, 89.5)
    albedo = near_ir_albedo(scene, cast(scene, depth_from_world, depth, ss))
    np.testing.assert_array_equal(
        render_ir_albedo(scene, depth_from_world, depth, ss), footprint_and_blur(albedo, ss, 0.0)
    )


def test_a_supersample_beyond_the_kernels_is_refused() -> None:
    scene, thermal_from_world, _ = _thermal_view("plate")
    with pytest.raises(ValueError, match="supersample must be 1-128"):
        render_aperture(scene, thermal_from_world, CAL.thermal, 129, 0.6, radiance_table())
    with pytest.raises(ValueError, match="supersample must be 1-128"):
        footprint_and_blur(np.zeros((4, 4)), 0, 0.0)
