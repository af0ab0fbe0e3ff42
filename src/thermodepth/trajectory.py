"""A moving rig's trajectory: the depth camera's pose in the world over time, and its file.

Poses are ``world_from_depth`` (p_world = R p_depth + t), in metres, on the frames' clock
(seconds). Between two poses the rotation is interpolated on the sphere (slerp) and the
translation linearly; before the first and after the last pose the end pose is held.

File format: TUM RGB-D (Sturm et al., IROS 2012, "A benchmark for the evaluation of RGB-D SLAM
systems"), one pose per line, ``timestamp tx ty tz qx qy qz qw`` (the camera's position and
orientation in the world, a unit quaternion with w last), ``#`` comments.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation, Slerp

from .camera import RigidTransform
from .errors import InputError

FloatArray = NDArray[np.float64]

TUM_HEADER = "# timestamp tx ty tz qx qy qz qw (world_from_depth, metres, seconds)"


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Poses ``world_from_depth`` at increasing times.

    times_s: (N,) strictly increasing, s; rotations: (N, 3, 3); translations_m: (N, 3).
    """

    times_s: FloatArray
    rotations: FloatArray
    translations_m: FloatArray

    def __post_init__(self) -> None:
        t = np.asarray(self.times_s, np.float64).reshape(-1)
        r = np.asarray(self.rotations, np.float64).reshape(-1, 3, 3)
        p = np.asarray(self.translations_m, np.float64).reshape(-1, 3)
        if not len(t) == len(r) == len(p) or len(t) == 0:
            raise ValueError("a trajectory needs one or more poses, as many rotations as times")
        if np.any(np.diff(t) <= 0):
            raise ValueError("a trajectory's times must increase")
        object.__setattr__(self, "times_s", t)
        object.__setattr__(self, "rotations", r)
        object.__setattr__(self, "translations_m", p)

    @classmethod
    def of_poses(cls, times_s: ArrayLike, poses: Sequence[RigidTransform]) -> Trajectory:
        """From ``world_from_depth`` transforms at ``times_s``."""
        return cls(
            np.asarray(times_s, np.float64),
            np.array([p.rotation for p in poses]).reshape(-1, 3, 3),
            np.array([p.translation_m for p in poses]).reshape(-1, 3),
        )

    def __len__(self) -> int:
        return len(self.times_s)

    def pose(self, i: int) -> RigidTransform:
        """The i-th pose, ``world_from_depth``."""
        return RigidTransform(self.rotations[i], self.translations_m[i], "world", "depth")

    def poses_at(self, times_s: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Rotations (M, 3, 3) and translations (M, 3) at ``times_s`` (M,): slerp and linear
        between poses, the end poses held outside them."""
        t = np.clip(np.asarray(times_s, np.float64).reshape(-1), self.times_s[0], self.times_s[-1])
        if len(self) == 1:
            return np.repeat(self.rotations, len(t), 0), np.repeat(self.translations_m, len(t), 0)
        rot = Slerp(self.times_s, Rotation.from_matrix(self.rotations))(t).as_matrix()
        pos = np.stack([np.interp(t, self.times_s, self.translations_m[:, k]) for k in range(3)])
        return rot.reshape(-1, 3, 3), pos.T

    def pose_at(self, time_s: float) -> RigidTransform:
        """``world_from_depth`` at ``time_s`` (interpolated)."""
        rot, pos = self.poses_at([time_s])
        return RigidTransform(rot[0], pos[0], "world", "depth")

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1] - self.times_s[0])

    @property
    def length_m(self) -> float:
        """The path's length, metres."""
        return float(np.linalg.norm(np.diff(self.translations_m, axis=0), axis=1).sum())

    def angular_speed_deg_s(self, times_s: ArrayLike, dt_s: float = 0.02) -> FloatArray:
        """How fast the camera turns at ``times_s``, degrees per second (central difference
        over ``dt_s``)."""
        t = np.asarray(times_s, np.float64).reshape(-1)
        r0, _ = self.poses_at(t - dt_s / 2)
        r1, _ = self.poses_at(t + dt_s / 2)
        rel = Rotation.from_matrix(np.einsum("nji,njk->nik", r0, r1))
        return np.degrees(rel.magnitude()) / dt_s

    # -- the TUM file ---------------------------------------------------------------------

    def tum_rows(self) -> FloatArray:
        """(N, 8) rows ``timestamp tx ty tz qx qy qz qw``."""
        q = Rotation.from_matrix(self.rotations).as_quat(canonical=True)
        return np.column_stack([self.times_s, self.translations_m, q])

    @classmethod
    def of_tum_rows(cls, rows: ArrayLike) -> Trajectory:
        """From (N, 8) rows ``timestamp tx ty tz qx qy qz qw`` (quaternions normalised)."""
        a = np.asarray(rows, np.float64).reshape(-1, 8)
        return cls(a[:, 0], Rotation.from_quat(a[:, 4:8]).as_matrix(), a[:, 1:4])

    def save_tum(self, path: str | Path) -> Path:
        """Write the TUM file at ``path``."""
        path = Path(path)
        # times to the nanosecond whatever the epoch, the rest to 9 significant digits
        body = "\n".join(
            f"{row[0]:.9f} " + " ".join(f"{v:.9g}" for v in row[1:]) for row in self.tum_rows()
        )
        path.write_text(f"{TUM_HEADER}\n{body}\n")
        return path

    @classmethod
    def load_tum(cls, path: str | Path) -> Trajectory:
        """Read a TUM file; a bad line is one :class:`InputError` naming the file and line."""
        path = Path(path)
        try:
            text = path.read_text()
        except OSError as exc:
            raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
        rows: list[list[float]] = []
        for n, line in enumerate(text.splitlines(), 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            fields = line.replace(",", " ").split()
            try:
                row = [float(f) for f in fields]
            except ValueError:
                raise InputError(f"{path}:{n}: not a number in {line!r}") from None
            if len(row) != 8:
                raise InputError(
                    f"{path}:{n}: {len(row)} fields; a TUM pose has 8 "
                    "(timestamp tx ty tz qx qy qz qw)"
                )
            if not np.all(np.isfinite(row)) or np.linalg.norm(row[4:]) < 1e-6:
                raise InputError(f"{path}:{n}: not a finite pose with a unit quaternion")
            if rows and row[0] <= rows[-1][0]:
                raise InputError(f"{path}:{n}: timestamp {row[0]} does not increase")
            rows.append(row)
        if not rows:
            raise InputError(f"{path}: no poses")
        return cls.of_tum_rows(rows)


def rigid_alignment(source_m: ArrayLike, target_m: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """The rotation R (3, 3) and translation t (3,) m minimising sum |target - (R source + t)|^2
    over paired points (N, 3) m, without scale (Horn 1987, "Closed-form solution of absolute
    orientation using unit quaternions", JOSA A 4(4); Umeyama 1991, "Least-squares
    estimation of transformation parameters between two point patterns", IEEE PAMI 13(4),
    whose sign correction keeps R a rotation). Points on one line leave the rotation about it
    undetermined."""
    src = np.asarray(source_m, np.float64).reshape(-1, 3)
    dst = np.asarray(target_m, np.float64).reshape(-1, 3)
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    u, _, vt = np.linalg.svd((dst - mu_d).T @ (src - mu_s))
    sign = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt)) or 1.0])
    rot = u @ sign @ vt
    return rot, mu_d - rot @ mu_s


def absolute_trajectory_error(estimate: Trajectory, truth: Trajectory) -> dict[str, Any]:
    """How far an estimated trajectory is from the truth, as the TUM RGB-D benchmark's ATE
    (Sturm et al., IROS 2012, section VI-B).

    The truth is interpolated at the estimate's times (which must lie within the truth's);
    the estimate's positions are aligned to it by the rigid motion that fits them best
    (:func:`rigid_alignment`: rotation and translation, no scale), since the two worlds'
    origins differ; the errors are the aligned positions' distances from the truth's.
    Returns, in metres: ``rmse_m`` (the ATE), ``mean_m``, ``median_m``, ``max_m``; in
    degrees, the angle of each aligned pose's rotation relative to the truth's (R_true^T R
    R_est, the relative rotation error): ``rotation_rmse_deg``, ``rotation_median_deg``,
    ``rotation_max_deg``; and the alignment, ``truth_from_estimate`` (a
    :class:`~thermodepth.camera.RigidTransform` from the estimate's world to the truth's).
    Three or more poses.
    """
    t = estimate.times_s
    slack_s = 1e-6  # times read back from a file round to its digits
    if t[0] < truth.times_s[0] - slack_s or t[-1] > truth.times_s[-1] + slack_s:
        raise InputError(
            f"the estimate's times ({t[0]:.3f}-{t[-1]:.3f} s) go beyond the truth's "
            f"({truth.times_s[0]:.3f}-{truth.times_s[-1]:.3f} s)"
        )
    if len(t) < 3:
        raise InputError(f"an absolute trajectory error needs 3 or more poses, got {len(t)}")
    rot_true, pos_true = truth.poses_at(t)
    rot, shift = rigid_alignment(estimate.translations_m, pos_true)
    err_m = np.linalg.norm(estimate.translations_m @ rot.T + shift - pos_true, axis=1)
    rel = np.einsum("nji,jk,nkl->nil", rot_true, rot, estimate.rotations)
    err_deg = np.degrees(Rotation.from_matrix(rel).magnitude())
    return {
        "rmse_m": float(np.sqrt(np.mean(err_m**2))),
        "mean_m": float(np.mean(err_m)),
        "median_m": float(np.median(err_m)),
        "max_m": float(np.max(err_m)),
        "rotation_rmse_deg": float(np.sqrt(np.mean(err_deg**2))),
        "rotation_median_deg": float(np.median(err_deg)),
        "rotation_max_deg": float(np.max(err_deg)),
        "truth_from_estimate": RigidTransform(rot, shift, "truth", "estimate"),
    }
