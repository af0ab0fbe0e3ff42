"""Accuracy of the system against the simulated rig's ground truth (tables and figures).

Lives below ``registration`` and ``sim`` in the house: it may import both.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .camera import RigidTransform
from .registration import REGISTRATION_METHODS, Reason, Registration
from .sim import DepthCameraModel, Rig, wall_scene


@dataclass(frozen=True)
class RegistrationError:
    """Registration error at one distance for one method (thermal pixels).

    median_px / p95_px: distance between the thermal position the method assigns to a depth
    pixel and the true one, over depth pixels the thermal camera sees; nearest_right: share of
    those whose nearest thermal pixel is the true one.
    """

    method: str
    distance_m: float
    median_px: float
    p95_px: float
    nearest_right: float


def registration_error(
    distance_m: float, method: str, seed: int = 0, depth_noise: bool = True
) -> RegistrationError:
    """Registration error of ``method`` for a wall facing the rig at ``distance_m``.

    Positions: ``"reproject"`` deprojects each measured depth and projects it into the thermal
    camera (what its kernels compute, in float64); ``"paper"`` uses its affine upscale map.
    The nearest-pixel check runs the method's own ``thermal_to_depth`` on an index image.
    """
    rig = Rig(
        wall_scene(distance_m),
        RigidTransform.identity("world", "depth"),
        seed=seed,
        depth_model=DepthCameraModel(noise=depth_noise),
    )
    frame = rig.frame()
    truth = rig.truth()
    cal = rig.calibration
    reg = Registration(cal, method=method)
    seen = truth.visible_in_thermal & (frame.depth > 0)
    v, u = np.nonzero(seen)
    if method == "paper":
        ut, vt = reg.thermal_pixel_of_depth()
        pos = np.stack([ut[v, u], vt[v, u]], axis=-1).astype(np.float64)
    else:
        z = frame.depth[seen] * cal.depth_scale_m
        pts = cal.thermal_from_depth.apply(cal.depth.deproject(np.stack([u, v], -1), z))
        pos = cal.thermal.project(pts)
    err = np.linalg.norm(pos - truth.thermal_pixel_of_depth[seen], axis=-1)
    h_t, w_t = cal.thermal.shape
    index = np.arange(h_t * w_t, dtype=np.float32).reshape(h_t, w_t)
    got, reason = reg.thermal_to_depth(frame.depth, index)
    true_px = np.floor(truth.thermal_pixel_of_depth[seen] + 0.5)
    true_index = true_px[:, 1] * w_t + true_px[:, 0]
    right = (reason[seen] == Reason.OK) & (got[seen] == true_index)
    return RegistrationError(
        method,
        distance_m,
        float(np.nanmedian(err)),
        float(np.nanpercentile(err, 95)),
        float(right.mean()),
    )


def registration_error_table(
    distances_m: tuple[float, ...] = (0.3, 0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.0),
    methods: tuple[str, ...] = REGISTRATION_METHODS,
) -> list[RegistrationError]:
    """:func:`registration_error` for every method and distance."""
    return [registration_error(d, m) for m in methods for d in distances_m]


def plot_registration_error(rows: list[RegistrationError], path: str | Path) -> Path:
    """Median and 95th-percentile error (thermal px) vs distance per method, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    floor = 1e-3  # errors below it (exact depth quanta) are drawn on it: log axis
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for method in sorted({r.method for r in rows}):
        sel = [r for r in rows if r.method == method]
        d = [r.distance_m for r in sel]
        med = [max(r.median_px, floor) for r in sel]
        line = ax.plot(d, med, "o-", label=f"{method}: median")[0]
        ax.plot(
            d,
            [max(r.p95_px, floor) for r in sel],
            "--",
            color=line.get_color(),
            label=f"{method}: 95th percentile",
        )
    ax.set_ylim(floor / 2, None)
    ax.set_yscale("log")
    ax.set_xlabel("distance to the wall (m)")
    ax.set_ylabel("registration error (thermal pixels)")
    ax.set_title(
        "Depth -> thermal correspondence error vs ground truth\n"
        "(errors below 0.001 px drawn at 0.001)",
        fontsize=10,
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out
