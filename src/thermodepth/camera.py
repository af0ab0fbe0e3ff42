"""Pinhole camera geometry: intrinsics, lens distortion, rigid transforms, projection.

Conventions (OpenCV): pixel centres at integer coordinates, so an image of width W spans
u in [-0.5, W - 0.5]; camera frame x right, y down, z forward (optical axis); distortion is
Brown-Conrady ``[k1, k2, p1, p2, k3]`` applied to normalised coordinates ``(X/Z, Y/Z)``.
Lengths in metres, angles in radians.

The paper's section 2.1 (Lin & Yao 2022, eqs 1-13) is here as plain functions:
:func:`rotation_from_euler` (eqs 1-4), :func:`world_to_camera` (eqs 5-6),
:func:`camera_to_image_plane` (eqs 7-10), :func:`image_plane_to_pixel` (eqs 11-12) and
:func:`projection_matrix` (eq 13). :class:`Intrinsics` adds lens distortion and vectorised
``project``/``deproject``; :class:`RigidTransform` names its frames (``thermal_from_depth``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

# ---------------------------------------------------------------------------------------------
# The paper's coordinate systems (section 2.1)
# ---------------------------------------------------------------------------------------------


def _axis_rotation(angle_rad: float, axis: int) -> FloatArray:
    """Passive rotation by ``angle_rad`` about coordinate axis ``axis`` (0=x, 1=y, 2=z)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m = np.eye(3)
    m[i, i] = m[j, j] = c
    m[i, j] = s
    m[j, i] = -s
    return m


def rotation_from_euler(phi: float, theta: float, omega: float) -> FloatArray:
    """Rotation matrix R = R1 R2 R3 of the paper's eqs (1)-(4), shape (3, 3).

    R1 rotates the axes about z by ``phi``, R2 about x by ``theta``, R3 about y by ``omega``
    (radians). Each is a *passive* (frame) rotation: it gives the coordinates of a fixed point
    in axes turned by the angle, counter-clockwise seen from the positive end of the axis,
    e.g. R1 = [[cos phi, sin phi, 0], [-sin phi, cos phi, 0], [0, 0, 1]]. The minus signs are
    lost in the paper's text; this is the convention of its Figure 3 (axes rotated by phi).
    Equivalently R = Rz(-phi) Rx(-theta) Ry(-omega) with active rotations Rz, Rx, Ry.
    """
    return _axis_rotation(phi, 2) @ _axis_rotation(theta, 0) @ _axis_rotation(omega, 1)


def world_to_camera(
    points_w_m: ArrayLike, rotation: ArrayLike, translation_m: ArrayLike
) -> FloatArray:
    """Camera-frame coordinates X_C = R X_W + T (eqs 5-6); points (..., 3) m -> (..., 3) m."""
    pts = np.asarray(points_w_m, dtype=np.float64)
    return pts @ np.asarray(rotation, dtype=np.float64).T + np.asarray(translation_m, np.float64)


def camera_to_image_plane(points_c_m: ArrayLike, focal_m: float) -> FloatArray:
    """Image-plane coordinates x = f X_C / Z_C, y = f Y_C / Z_C (eqs 7-10), metres.

    points_c_m: (..., 3) camera-frame points in metres; focal_m: focal length in metres.
    Returns (..., 2) positions on the sensor, origin at the optical axis.
    """
    pts = np.asarray(points_c_m, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return focal_m * pts[..., :2] / pts[..., 2:3]


def image_plane_to_pixel(
    xy_m: ArrayLike, pixel_pitch_m: tuple[float, float], principal_point_px: tuple[float, float]
) -> FloatArray:
    """Pixel coordinates u = x / dx + u0, v = y / dy + v0 (eqs 11-12).

    xy_m: (..., 2) image-plane positions in metres; pixel_pitch_m: (dx, dy) metres per pixel;
    principal_point_px: (u0, v0). Returns (..., 2) pixels.
    """
    xy = np.asarray(xy_m, dtype=np.float64)
    return xy / np.asarray(pixel_pitch_m, np.float64) + np.asarray(principal_point_px, np.float64)


def projection_matrix(
    focal_m: float,
    pixel_pitch_m: tuple[float, float],
    principal_point_px: tuple[float, float],
    rotation: ArrayLike,
    translation_m: ArrayLike,
) -> FloatArray:
    """The 3x4 matrix of eq (13): Z_C [u v 1]^T = K [I|0] [[R, T], [0, 1]] [X_W 1]^T."""
    dx, dy = pixel_pitch_m
    u0, v0 = principal_point_px
    k = np.array([[focal_m / dx, 0.0, u0], [0.0, focal_m / dy, v0], [0.0, 0.0, 1.0]])
    rt = np.hstack([np.asarray(rotation, np.float64), np.reshape(translation_m, (3, 1))])
    return k @ rt


def project_with_matrix(points_w_m: ArrayLike, matrix: ArrayLike) -> FloatArray:
    """Pixels (..., 2) of world points (..., 3) through a 3x4 projection matrix (eq 13)."""
    pts = np.asarray(points_w_m, dtype=np.float64)
    m = np.asarray(matrix, dtype=np.float64)
    h = pts @ m[:, :3].T + m[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        return h[..., :2] / h[..., 2:3]


# ---------------------------------------------------------------------------------------------
# Lens distortion (OpenCV Brown-Conrady model)
# ---------------------------------------------------------------------------------------------


def distort(x: FloatArray, y: FloatArray, distortion: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Apply Brown-Conrady distortion ``[k1, k2, p1, p2, k3]`` to normalised coordinates.

    x, y: undistorted normalised coordinates X/Z, Y/Z (any shape). Returns distorted (x, y)
    as in OpenCV's projectPoints.
    """
    k1, k2, p1, p2, k3 = np.asarray(distortion, dtype=np.float64)
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xy2 = 2.0 * x * y
    xd = x * radial + p1 * xy2 + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + p2 * xy2
    return xd, yd


def undistort(
    xd: FloatArray, yd: FloatArray, distortion: ArrayLike, iterations: int = 20
) -> tuple[FloatArray, FloatArray]:
    """Invert :func:`distort` by Newton's method; normalised coordinates in and out.

    Converges to ~1e-15 within the radius where the distortion is monotonic (see
    :func:`monotonic_radius2`); beyond it the inverse is not unique.
    """
    k1, k2, p1, p2, k3 = np.asarray(distortion, dtype=np.float64)
    xd = np.asarray(xd, dtype=np.float64)
    yd = np.asarray(yd, dtype=np.float64)
    if not np.any([k1, k2, p1, p2, k3]):
        return xd.copy(), yd.copy()
    x, y = xd.copy(), yd.copy()
    for _ in range(iterations):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r2
        fx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd
        fy = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd
        # Jacobian of the distortion map
        jxx = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
        jxy = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
        jyx = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
        jyy = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
        det = jxx * jyy - jxy * jyx
        with np.errstate(divide="ignore", invalid="ignore"):
            dx = (jyy * fx - jxy * fy) / det
            dy = (jxx * fy - jyx * fx) / det
        x, y = x - dx, y - dy
        # converged everywhere: further steps change nothing (NaN steps never count as done)
        if np.all(np.abs(dx) < 1e-15) and np.all(np.abs(dy) < 1e-15):
            break
    return x, y


def monotonic_radius2(distortion: ArrayLike, r_max: float = 4.0) -> float:
    """Largest r^2 (normalised) up to which the radial distortion r (1 + k1 r^2 + ...) grows.

    Past this radius the polynomial folds back: points far off axis would project back into
    the image. Returns ``r_max**2`` when no fold occurs before ``r_max`` (about 76 degrees).
    """
    k1, k2, _, _, k3 = np.asarray(distortion, dtype=np.float64)
    r = np.linspace(0.0, r_max, 40001)
    r2 = r * r
    slope = 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2 + 7.0 * k3 * r2 * r2 * r2
    bad = np.flatnonzero(slope <= 0.0)
    return float(r2[bad[0] - 1]) if bad.size else r_max * r_max


# ---------------------------------------------------------------------------------------------
# Intrinsics
# ---------------------------------------------------------------------------------------------


def _readonly(a: ArrayLike, shape: tuple[int, ...]) -> FloatArray:
    arr = np.array(a, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"expected shape {shape}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Intrinsics:
    """Pinhole intrinsics with Brown-Conrady distortion, OpenCV conventions.

    width, height: image size in pixels; fx, fy: focal lengths in pixels; cx, cy: principal
    point in pixels (pixel centres at integers); distortion: [k1, k2, p1, p2, k3].
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: FloatArray = field(default_factory=lambda: np.zeros(5))

    def __post_init__(self) -> None:
        object.__setattr__(self, "distortion", _readonly(self.distortion, (5,)))
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")

    def _key(self) -> tuple[float, ...]:
        return (
            self.width,
            self.height,
            self.fx,
            self.fy,
            self.cx,
            self.cy,
            *self.distortion.tolist(),
        )

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Intrinsics) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    @property
    def matrix(self) -> FloatArray:
        """The 3x3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape as numpy sees it: (height, width)."""
        return (self.height, self.width)

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.distortion != 0.0))

    @property
    def hfov_deg(self) -> float:
        """Horizontal field of view of the pinhole (no distortion), degrees."""
        return float(np.degrees(2.0 * np.arctan(self.width / 2.0 / self.fx)))

    @cached_property
    def max_radius2(self) -> float:
        """Normalised r^2 beyond which projection is refused (distortion would fold)."""
        return monotonic_radius2(self.distortion)

    def project(self, points_m: ArrayLike) -> FloatArray:
        """Pixels (..., 2) of camera-frame points (..., 3) in metres.

        NaN where the point is not in front of the camera (Z <= 0) or lies beyond the radius
        where the distortion polynomial is monotonic. Matches cv2.projectPoints elsewhere.
        """
        pts = np.asarray(points_m, dtype=np.float64)
        z = pts[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = pts[..., 0] / z
            y = pts[..., 1] / z
        bad = ~(z > 0) | (x * x + y * y > self.max_radius2)
        xd, yd = distort(x, y, self.distortion) if self.has_distortion else (x, y)
        out = np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=-1)
        out[bad] = np.nan
        return out

    def normalized_from_pixels(self, pixels: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Undistorted normalised coordinates (x, y) = (X/Z, Y/Z) of pixels (..., 2)."""
        px = np.asarray(pixels, dtype=np.float64)
        xd = (px[..., 0] - self.cx) / self.fx
        yd = (px[..., 1] - self.cy) / self.fy
        return undistort(xd, yd, self.distortion)

    def deproject(self, pixels: ArrayLike, depth_m: ArrayLike) -> FloatArray:
        """Camera-frame points (..., 3) in metres of pixels (..., 2) at depth Z = ``depth_m``.

        ``depth_m`` is the distance along the optical axis (what a depth camera reports), not
        the range along the ray; it broadcasts against the pixels' leading shape.
        """
        x, y = self.normalized_from_pixels(pixels)
        z = np.asarray(depth_m, dtype=np.float64)
        x, y, z = np.broadcast_arrays(x, y, z)
        return np.stack([x * z, y * z, z], axis=-1)

    def pixel_grid(self) -> tuple[FloatArray, FloatArray]:
        """Pixel-centre coordinates (u, v), each of shape (height, width)."""
        u = np.arange(self.width, dtype=np.float64)
        v = np.arange(self.height, dtype=np.float64)
        uu, vv = np.meshgrid(u, v)
        return uu, vv

    def contains(self, pixels: ArrayLike) -> NDArray[np.bool_]:
        """True where pixels (..., 2) fall inside the image (edges at -0.5 and size - 0.5)."""
        px = np.asarray(pixels, dtype=np.float64)
        u, v = px[..., 0], px[..., 1]
        return (u >= -0.5) & (u < self.width - 0.5) & (v >= -0.5) & (v < self.height - 0.5)


@lru_cache(maxsize=16)
def _rays(intr: Intrinsics, supersample: int, corners: bool) -> tuple[FloatArray, FloatArray]:
    if corners:
        u = np.arange(intr.width + 1) - 0.5
        v = np.arange(intr.height + 1) - 0.5
    else:  # sub-pixel centres: pixel u spans u - 0.5 .. u + 0.5 in `supersample` cells
        offs = (np.arange(supersample) + 0.5) / supersample - 0.5
        u = (np.arange(intr.width)[:, None] + offs).ravel()
        v = (np.arange(intr.height)[:, None] + offs).ravel()
    uu, vv = np.meshgrid(u, v)
    x, y = intr.normalized_from_pixels(np.stack([uu, vv], axis=-1))
    x, y = np.ascontiguousarray(x), np.ascontiguousarray(y)
    x.setflags(write=False)
    y.setflags(write=False)
    return x, y


def pixel_rays(intr: Intrinsics, supersample: int = 1) -> tuple[FloatArray, FloatArray]:
    """Undistorted normalised coordinates (x, y) of every pixel centre, each (H, W) (with
    ``supersample``: of every sub-pixel centre, (H ss, W ss)). Cached per camera; read-only."""
    return _rays(intr, supersample, False)


def corner_rays(intr: Intrinsics) -> tuple[FloatArray, FloatArray]:
    """Undistorted normalised coordinates (x, y) of every pixel corner, each (H + 1, W + 1):
    corner [j, i] is at pixel position (i - 0.5, j - 0.5). Cached per camera; read-only."""
    return _rays(intr, 1, True)


# ---------------------------------------------------------------------------------------------
# Rigid transforms
# ---------------------------------------------------------------------------------------------


class FrameMismatchError(ValueError):
    """Two transforms were composed whose frames do not meet."""


def is_rotation(matrix: ArrayLike, tol: float = 1e-6) -> bool:
    """True if ``matrix`` is a proper rotation: R^T R = I within ``tol`` and det R = +1."""
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        return False
    return bool(np.max(np.abs(m.T @ m - np.eye(3))) <= tol and np.linalg.det(m) > 0)


@dataclass(frozen=True, eq=False)
class RigidTransform:
    """Rigid transform ``<to>_from_<from>``: p_to = rotation @ p_from + translation_m.

    rotation: (3, 3) proper rotation; translation_m: (3,) metres. Compose with ``@``:
    ``thermal_from_depth @ depth_from_world`` gives ``thermal_from_world``; composing
    transforms whose frames do not meet raises :class:`FrameMismatchError`.
    """

    rotation: FloatArray
    translation_m: FloatArray
    to_frame: str
    from_frame: str

    def __post_init__(self) -> None:
        object.__setattr__(self, "rotation", _readonly(self.rotation, (3, 3)))
        object.__setattr__(self, "translation_m", _readonly(self.translation_m, (3,)))
        if not is_rotation(self.rotation):
            raise ValueError(f"{self.name}: rotation is not orthonormal with det +1")

    @classmethod
    def identity(cls, to_frame: str, from_frame: str) -> RigidTransform:
        return cls(np.eye(3), np.zeros(3), to_frame, from_frame)

    @property
    def name(self) -> str:
        return f"{self.to_frame}_from_{self.from_frame}"

    @property
    def angle_deg(self) -> float:
        """Angle of the rotation (axis-angle magnitude), degrees."""
        c = (float(np.trace(self.rotation)) - 1.0) / 2.0
        return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))

    @property
    def distance_m(self) -> float:
        """Length of the translation: how far apart the two frames' origins are, metres."""
        return float(np.linalg.norm(self.translation_m))

    @property
    def matrix(self) -> FloatArray:
        """Homogeneous 4x4 matrix [[R, t], [0, 1]] (eq 6)."""
        m = np.eye(4)
        m[:3, :3] = self.rotation
        m[:3, 3] = self.translation_m
        return m

    def apply(self, points_m: ArrayLike) -> FloatArray:
        """Transform points (..., 3) from ``from_frame`` to ``to_frame``."""
        return world_to_camera(points_m, self.rotation, self.translation_m)

    def inverse(self) -> RigidTransform:
        rt = self.rotation.T
        return RigidTransform(rt, -rt @ self.translation_m, self.from_frame, self.to_frame)

    def __matmul__(self, other: RigidTransform) -> RigidTransform:
        if self.from_frame != other.to_frame:
            raise FrameMismatchError(
                f"cannot compose {self.name} with {other.name}: "
                f"'{self.from_frame}' != '{other.to_frame}'"
            )
        return RigidTransform(
            self.rotation @ other.rotation,
            self.rotation @ other.translation_m + self.translation_m,
            self.to_frame,
            other.from_frame,
        )

    def __repr__(self) -> str:
        return (
            f"RigidTransform({self.name}, rotation={self.rotation.tolist()}, "
            f"translation_m={self.translation_m.tolist()})"
        )
