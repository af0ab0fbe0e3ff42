"""Scenes for the simulated rig: rectangles and boxes with temperature and emissivity.

World frame: x right, y down, z forward (a camera at the identity pose looks along +z), in
metres. Every surface is a :class:`Rect` (a box is six of them); a rect may carry a pattern
(checkerboard or asymmetric circle grid) that switches between two materials, for
calibration targets. Surfaces are seen from both sides.

Defaults reproduce the paper's setup (Lin & Yao 2022, section 4): a 30 x 30 cm heating plate at
39 C with emissivity 0.95 (the paper's "0.03" is the brass element's, not the plastic
surface's), an optional chip on it, and a background wall and floor at the 25 C ambient, 50 %
relative humidity.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..board import BoardSpec
from ..camera import RigidTransform, rotation_from_euler
from ..radiometry import ZERO_C_IN_K

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Material:
    """Surface properties: temp_k (K), LWIR emissivity (0..1], ir_albedo (near-IR, 0..1).

    emissivity is the normal one. directional: it falls at oblique views as a smooth
    surface's does (:func:`~thermodepth.radiometry.fresnel_emissivity`; otherwise the same
    at every angle); specular: the surface reflects, as a mirror, what its mirrored ray sees
    (otherwise it reflects the ambient, a diffuse surface in a uniform room).
    """

    temp_k: float
    emissivity: float = 0.95
    ir_albedo: float = 0.5
    name: str = ""
    directional: bool = False
    specular: bool = False

    def __post_init__(self) -> None:
        if not 0 < self.emissivity <= 1:
            raise ValueError(f"material {self.name!r}: emissivity must be in (0, 1]")
        if not self.temp_k > 0:
            raise ValueError(f"material {self.name!r}: temp_k must be positive")


@dataclass(frozen=True)
class Checkerboard:
    """A checkerboard of (board.cols + 1) x (board.rows + 1) squares centred on the rect,
    with the board's inner corners at :meth:`BoardSpec.object_points_m`. The square at the
    top-left (most negative s, q) is of the rect's first material, the next of the second."""

    board: BoardSpec

    @property
    def size_m(self) -> tuple[float, float]:
        s = self.board.spacing_m
        return ((self.board.cols + 1) * s, (self.board.rows + 1) * s)

    def second_material(self, s: FloatArray, q: FloatArray) -> NDArray[np.bool_]:
        n_u, n_v = self.board.cols + 1, self.board.rows + 1
        i = np.floor(s / self.board.spacing_m + n_u / 2.0)
        j = np.floor(q / self.board.spacing_m + n_v / 2.0)
        inside = (i >= 0) & (i < n_u) & (j >= 0) & (j < n_v)
        return inside & ((i + j) % 2 == 1)


@dataclass(frozen=True)
class CircleGrid:
    """OpenCV's asymmetric circle grid (circles of ``diameter_m`` at the board's points)."""

    board: BoardSpec
    diameter_m: float

    @property
    def size_m(self) -> tuple[float, float]:
        pts = self.board.object_points_m()
        return (
            float(np.ptp(pts[:, 0])) + self.diameter_m,
            float(np.ptp(pts[:, 1])) + self.diameter_m,
        )

    def second_material(self, s: FloatArray, q: FloatArray) -> NDArray[np.bool_]:
        out = np.zeros(np.shape(s), dtype=bool)
        r2 = (self.diameter_m / 2) ** 2
        for cx, cy, _ in self.board.object_points_m():
            out |= (s - cx) ** 2 + (q - cy) ** 2 <= r2
        return out


def board_pattern(board: BoardSpec) -> Checkerboard | CircleGrid:
    """The printed pattern of a board: circles have the diameter of the grid step s."""
    if board.kind == "checkerboard":
        return Checkerboard(board)
    return CircleGrid(board, board.spacing_m)


Pattern = Checkerboard | CircleGrid


@dataclass(frozen=True, eq=False)
class Rect:
    """A rectangle: centre (3,), unit in-plane axes u and v (3,), half sizes along them.

    Local coordinates of a point p on it: s = u . (p - centre), q = v . (p - centre), with
    |s| <= half_u_m and |q| <= half_v_m. normal = u x v.
    """

    center_m: FloatArray
    axis_u: FloatArray
    axis_v: FloatArray
    half_u_m: float
    half_v_m: float
    material: Material
    pattern: Pattern | None = None
    material_b: Material | None = None
    name: str = ""

    def __post_init__(self) -> None:
        u = np.asarray(self.axis_u, np.float64)
        v = np.asarray(self.axis_v, np.float64)
        u, v = u / np.linalg.norm(u), v / np.linalg.norm(v)
        if abs(u @ v) > 1e-9:
            raise ValueError(f"rect {self.name!r}: axes must be orthogonal")
        object.__setattr__(self, "center_m", np.asarray(self.center_m, np.float64))
        object.__setattr__(self, "axis_u", u)
        object.__setattr__(self, "axis_v", v)
        if (self.pattern is None) != (self.material_b is None):
            raise ValueError(f"rect {self.name!r}: a pattern needs a second material")

    @property
    def normal(self) -> FloatArray:
        return np.cross(self.axis_u, self.axis_v)

    def point_m(self, s: ArrayLike, q: ArrayLike) -> FloatArray:
        """World points (..., 3) at local coordinates (s, q)."""
        s = np.asarray(s, np.float64)[..., None]
        q = np.asarray(q, np.float64)[..., None]
        return self.center_m + s * self.axis_u + q * self.axis_v

    def boundary_m(self, per_edge: int = 32) -> FloatArray:
        """Points (4 * per_edge, 3) along the rect's edges."""
        t = np.linspace(-1.0, 1.0, per_edge)
        one = np.ones_like(t)
        s = np.concatenate([t, one, -t, -one]) * self.half_u_m
        q = np.concatenate([-one, t, one, -t]) * self.half_v_m
        return self.point_m(s, q)


def box(
    center_m: ArrayLike,
    size_m: tuple[float, float, float],
    material: Material,
    rotation: ArrayLike | None = None,
    name: str = "box",
) -> list[Rect]:
    """Six rects forming a box of ``size_m`` (x, y, z) centred at ``center_m``, rotated."""
    rot = np.eye(3) if rotation is None else np.asarray(rotation, np.float64)
    c = np.asarray(center_m, np.float64)
    half = np.asarray(size_m, np.float64) / 2
    faces = []
    for axis in range(3):
        a, b = [k for k in range(3) if k != axis]
        for sign in (-1.0, 1.0):
            offset = np.zeros(3)
            offset[axis] = sign * half[axis]
            faces.append(
                Rect(
                    c + rot @ offset,
                    rot[:, a],
                    rot[:, b],
                    half[a],
                    half[b],
                    material,
                    name=f"{name}{'-+'[sign > 0]}{'xyz'[axis]}",
                )
            )
    return faces


@dataclass(frozen=True, eq=False)
class RectArrays:
    """A scene's rects as arrays: center_m, axis_u, axis_v, normal (R, 3) and half_m (R, 2)
    (half sizes along u and v), metres."""

    center_m: FloatArray
    axis_u: FloatArray
    axis_v: FloatArray
    normal: FloatArray
    half_m: FloatArray

    @classmethod
    def of(cls, rects: tuple[Rect, ...]) -> RectArrays:
        def stack(values: list[FloatArray]) -> FloatArray:
            return np.array(values, dtype=np.float64).reshape(-1, 3)

        return cls(
            stack([r.center_m for r in rects]),
            stack([r.axis_u for r in rects]),
            stack([r.axis_v for r in rects]),
            stack([r.normal for r in rects]),
            np.array([[r.half_u_m, r.half_v_m] for r in rects], np.float64).reshape(-1, 2),
        )

    def points_m(self, rect: NDArray[np.int64], s_m: FloatArray, q_m: FloatArray) -> FloatArray:
        """World points (N, 3) at local coordinates (s, q) (N,) on rects ``rect`` (N,)."""
        return (
            self.center_m[rect]
            + s_m[:, None] * self.axis_u[rect]
            + q_m[:, None] * self.axis_v[rect]
        )


@dataclass(frozen=True, eq=False)
class Scene:
    """Surfaces plus the air: ambient (and reflected) temperature, relative humidity.

    Rays that hit nothing see an enclosure at the ambient temperature (thermal) and no depth.
    """

    rects: tuple[Rect, ...]
    ambient_temp_k: float = 25.0 + ZERO_C_IN_K
    relative_humidity: float = 0.5
    names: dict[str, int] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "rects", tuple(self.rects))
        object.__setattr__(self, "names", {r.name: i for i, r in enumerate(self.rects)})

    def index(self, name: str) -> int:
        return self.names[name]

    @cached_property
    def geometry(self) -> RectArrays:
        """The rects as arrays (for vectorised work on many points)."""
        return RectArrays.of(self.rects)

    @cached_property
    def corners_m(self) -> FloatArray:
        """Each rect's corners (R, 4, 3), in order round it: (-u, -v), (+u, -v), (+u, +v),
        (-u, +v)."""
        signs = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
        return np.array(
            [r.point_m(signs[:, 0] * r.half_u_m, signs[:, 1] * r.half_v_m) for r in self.rects],
            np.float64,
        ).reshape(-1, 4, 3)

    @property
    def materials(self) -> tuple[Material, ...]:
        """Every material of the rects (a patterned rect's two)."""
        both = ((r.material, r.material_b) for r in self.rects)
        return tuple(m for pair in both for m in pair if m is not None)

    @cached_property
    def has_optics(self) -> bool:
        """Whether a material is directional or specular (the thermal render then needs the
        viewing direction)."""
        return any(m.directional or m.specular for m in self.materials)


def plate_scene(
    plate_temp_c: float = 39.0,
    ambient_temp_c: float = 25.0,
    relative_humidity: float = 0.5,
    plate_size_m: float = 0.30,
    plate_emissivity: float = 0.95,
    chip_temp_c: float | None = None,
    chip_size_m: float = 0.02,
    chip_offset_m: tuple[float, float] = (0.06, -0.05),
    wall_gap_m: float = 1.2,
    floor_drop_m: float = 0.5,
) -> Scene:
    """The paper's setup: a heating plate facing -z at the world origin, wall and floor.

    Plate: ``plate_size_m`` square at ``plate_temp_c`` (emissivity 0.95: a thin plastic
    cover; the paper's 0.03 is the brass heating element under it). Chip (optional): a box
    ``chip_size_m`` square and 3 mm thick at ``chip_temp_c`` on the plate's face, offset
    ``chip_offset_m`` (right, down) from the centre. Wall ``wall_gap_m`` behind the plate, floor
    ``floor_drop_m`` below its centre, both at ambient with emissivity 0.9.
    """
    k = ZERO_C_IN_K
    ambient = Material(ambient_temp_c + k, 0.9, 0.6, "ambient")
    half = plate_size_m / 2
    ex, ey = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    rects = [
        Rect(
            np.zeros(3),
            ex,
            ey,
            half,
            half,
            Material(plate_temp_c + k, plate_emissivity, 0.3, "plate"),
            name="plate",
        ),
        Rect(np.array([0, 0, wall_gap_m]), ex, ey, 6.0, 4.0, ambient, name="wall"),
        Rect(
            np.array([0, floor_drop_m, wall_gap_m - 4.0]),
            ex,
            np.array([0, 0, 1.0]),
            6.0,
            4.0,
            ambient,
            name="floor",
        ),
    ]
    if chip_temp_c is not None:
        t = 0.003
        chip = Material(chip_temp_c + k, 0.95, 0.2, "chip")
        rects += box(
            [chip_offset_m[0], chip_offset_m[1], -t / 2],
            (chip_size_m, chip_size_m, t),
            chip,
            name="chip",
        )
    return Scene(tuple(rects), ambient_temp_c + k, relative_humidity)


def wall_scene(
    distance_m: float,
    temp_c: float = 25.0,
    emissivity: float = 0.95,
    ambient_temp_c: float = 25.0,
    relative_humidity: float = 0.5,
) -> Scene:
    """A uniform wall facing the camera at ``distance_m`` (along +z), filling the view."""
    k = ZERO_C_IN_K
    wall = Rect(
        np.array([0, 0, distance_m]),
        np.array([1.0, 0, 0]),
        np.array([0, 1.0, 0]),
        50.0,
        50.0,
        Material(temp_c + k, emissivity, 0.5, "wall"),
        name="wall",
    )
    return Scene((wall,), ambient_temp_c + k, relative_humidity)


def occlusion_scene(
    box_temp_c: float = 60.0,
    box_distance_m: float = 0.8,
    wall_distance_m: float = 2.0,
    ambient_temp_c: float = 25.0,
    box_size_m: tuple[float, float, float] = (0.25, 0.25, 0.25),
    box_offset_m: tuple[float, float] = (0.0, 0.0),
) -> Scene:
    """A hot box in front of a wall (plus a warmer stripe on the wall), for occlusion tests.

    Distances are along +z from a camera at the world origin.
    """
    k = ZERO_C_IN_K
    wall = Material(ambient_temp_c + k, 0.9, 0.6, "wall")
    stripe = Material(ambient_temp_c + 8 + k, 0.9, 0.4, "stripe")
    ex, ey = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    rects = [
        Rect(np.array([0, 0, wall_distance_m]), ex, ey, 8.0, 6.0, wall, name="wall"),
        Rect(np.array([0, 0, wall_distance_m - 0.001]), ex, ey, 0.05, 3.0, stripe, name="stripe"),
    ]
    zc = box_distance_m + box_size_m[2] / 2
    rects += box(
        [box_offset_m[0], box_offset_m[1], zc],
        box_size_m,
        Material(box_temp_c + k, 0.95, 0.3, "box"),
        name="box",
    )
    return Scene(tuple(rects), ambient_temp_c + k, 0.5)


BOARD_STYLES: dict[str, str] = {
    "bare": "bare aluminium (emissivity 0.10, bright in near-IR) with the pattern painted on "
    "(0.95, dark); a margin of bare metal around it",
    "plate": "a heated plate painted matt (0.95, dark in near-IR) with the pattern in aluminium "
    "tape (0.10, bright): hot squares inside a uniform hot margin of the plate",
    "mask": "a cut-out mask at room temperature (card: 0.90, bright in near-IR) in front of a "
    "warm plate (0.95, dark) that shows through the holes; a margin of the mask",
}
"""How calibration boards are made (``target_scene``'s ``style``), as both cameras see them."""


def target_scene(
    pattern: Pattern,
    board_temp_c: float = 45.0,
    ambient_temp_c: float = 25.0,
    margin_m: float | None = None,
    board_pose: RigidTransform | None = None,
    style: str = "bare",
) -> Scene:
    """A heated calibration board of ``style`` (:data:`BOARD_STYLES`) seen against a far
    ambient wall.

    The pattern switches between two materials; the board's base material surrounds it as a
    uniform margin ``margin_m`` wide (default: 4 cm for ``bare``, 1.5 grid steps for the
    others). In LWIR a high-emissivity surface glows at its temperature and a low-emissivity
    one mostly reflects the cooler room, so the thermal image's polarity is set by the
    emissivities, the IR image's by the near-IR albedos. ``board_pose`` maps the board's
    (s, q, normal) frame to the world (default: at the origin, facing -z).
    """
    k = ZERO_C_IN_K
    hot, room = board_temp_c + k, ambient_temp_c + k
    materials = {
        "bare": (Material(hot, 0.10, 0.85, "metal"), Material(hot, 0.95, 0.08, "paint")),
        "plate": (Material(hot, 0.95, 0.08, "paint"), Material(hot, 0.10, 0.85, "tape")),
        "mask": (Material(room, 0.90, 0.80, "card"), Material(hot, 0.95, 0.10, "plate")),
    }
    if style not in materials:
        raise ValueError(f"unknown board style {style!r}; choose from {sorted(materials)}")
    base, painted = materials[style]
    if margin_m is None:
        margin_m = 0.04 if style == "bare" else 1.5 * pattern.board.spacing_m
    w, h = pattern.size_m
    pose = board_pose or RigidTransform.identity("world", "board")
    rot, c = pose.rotation, pose.translation_m
    board = Rect(
        c,
        rot[:, 0],
        rot[:, 1],
        w / 2 + margin_m,
        h / 2 + margin_m,
        base,
        pattern,
        painted,
        name="board",
    )
    wall = Material(room, 0.9, 0.5, "wall")
    far = Rect(c + rot[:, 2] * 2.5, rot[:, 0], rot[:, 1], 12.0, 9.0, wall, name="wall")
    return Scene((board, far), room, 0.5)


def camera_pose(
    distance_m: float,
    yaw_deg: float = 0.0,
    pitch_deg: float = 0.0,
    roll_deg: float = 0.0,
    target_m: ArrayLike = (0.0, 0.0, 0.0),
    offset_m: ArrayLike = (0.0, 0.0),
) -> RigidTransform:
    """``world_from_depth`` for a camera ``distance_m`` in front of ``target_m`` (along -z).

    The camera looks along +z, turned by yaw (about y), pitch (about x) and roll (about z),
    then moved sideways by ``offset_m`` (x, y) in its own frame.
    """
    rot = rotation_from_euler(np.radians(roll_deg), np.radians(pitch_deg), np.radians(yaw_deg)).T
    centre = np.asarray(target_m, np.float64) - rot @ np.array([0.0, 0.0, distance_m])
    centre = centre + rot @ np.array([*np.asarray(offset_m, np.float64), 0.0])
    return RigidTransform(rot, centre, "world", "depth")
