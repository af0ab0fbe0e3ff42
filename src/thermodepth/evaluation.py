"""Accuracy of the system against the simulated rig's ground truth (tables and figures).

Lives below ``registration`` and ``sim`` in the house: it may import both.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .calibration import Calibration
from .camera import RigidTransform
from .compensation import (
    CompensationModel,
    PaperModel,
    RadianceModel,
    apply_to_table,
    overall,
)
from .frames import FramePair
from .registration import REGISTRATION_METHODS, Reason, Registration
from .sim import DepthCameraModel, Rig, default_calibration, wall_scene
from .sim.protocols import SweepConfig, simulate_sweep
from .sim.rig import GroundTruth
from .sweep import SweepTable

FloatArray = NDArray[np.float64]


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


def _wall(
    distance_m: float, seed: int, depth_noise: bool, calibration: Calibration
) -> tuple[FramePair, GroundTruth]:
    """The first frame of a wall facing the rig at ``distance_m``, and its truth."""
    rig = Rig(
        wall_scene(distance_m),
        RigidTransform.identity("world", "depth"),
        seed=seed,
        depth_model=DepthCameraModel(noise=depth_noise),
        calibration=calibration,
    )
    return rig.frame(), rig.truth()


def _score(
    reg: Registration, frame: FramePair, truth: GroundTruth, distance_m: float
) -> RegistrationError:
    """Registration error of ``reg`` on a frame, against its truth (see registration_error)."""
    cal = reg.calibration
    seen = truth.visible_in_thermal & (frame.depth > 0)
    ut, vt = reg.thermal_pixel_of_depth(frame.depth)
    pos = np.stack([ut[seen], vt[seen]], axis=-1).astype(np.float64)
    err = np.linalg.norm(pos - truth.thermal_pixel_of_depth[seen], axis=-1)
    h_t, w_t = cal.thermal.shape
    index = np.arange(h_t * w_t, dtype=np.float32).reshape(h_t, w_t)
    got, reason = reg.thermal_to_depth(frame.depth, index)
    true_px = np.floor(truth.thermal_pixel_of_depth[seen] + 0.5)
    true_index = true_px[:, 1] * w_t + true_px[:, 0]
    right = (reason[seen] == Reason.OK) & (got[seen] == true_index)
    return RegistrationError(
        reg.method,
        distance_m,
        float(np.nanmedian(err)),
        float(np.nanpercentile(err, 95)),
        float(right.mean()),
    )


def registration_error(
    distance_m: float,
    method: str,
    seed: int = 0,
    depth_noise: bool = True,
    calibration: Calibration | None = None,
) -> RegistrationError:
    """Registration error of ``method`` for a wall facing the rig at ``distance_m`` (the rig's
    ``calibration``: None, the default cameras'; :func:`~.sim.cameras.rig_calibration`).

    Positions: ``"reproject"`` deprojects each measured depth and projects it into the thermal
    camera (what its kernels compute, in float64); ``"paper"`` uses its affine upscale map.
    The nearest-pixel check runs the method's own ``thermal_to_depth`` on an index image.
    """
    cal = calibration or default_calibration()
    frame, truth = _wall(distance_m, seed, depth_noise, cal)
    return _score(Registration(cal, method), frame, truth, distance_m)


def registration_error_table(
    distances_m: tuple[float, ...] = (0.3, 0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.0),
    methods: tuple[str, ...] = tuple(REGISTRATION_METHODS),
) -> list[RegistrationError]:
    """:func:`registration_error` for every method and distance (each wall rendered once,
    each method's registration built once), method by method."""
    cal = default_calibration()
    regs = [Registration(cal, m) for m in methods]
    by_distance = []
    for d in distances_m:
        frame, truth = _wall(d, 0, True, cal)
        by_distance.append([_score(reg, frame, truth, d) for reg in regs])
    return [row[i] for i in range(len(regs)) for row in by_distance]


def registration_difference_px(
    reference: Calibration,
    other: Calibration,
    depths_m: Sequence[float] = (0.5, 1.0, 2.0, 3.0),
    step_px: int = 8,
) -> FloatArray:
    """How far apart (thermal pixels) two calibrations put the same depth pixels (every
    ``step_px``-th each way, at each of ``depths_m``), over those ``reference`` maps inside
    the thermal image; NaN where ``other`` maps a point nowhere (its distortion guard)."""
    u, v = reference.depth.pixel_grid()
    pix = np.stack([u[::step_px, ::step_px], v[::step_px, ::step_px]], axis=-1)
    errors = []
    for z in depths_m:
        pa, pb = (
            c.thermal.project(c.thermal_from_depth.apply(c.depth.deproject(pix, z)))
            for c in (reference, other)
        )
        inside = reference.thermal.contains(pa)
        errors.append(np.linalg.norm(pa[inside] - pb[inside], axis=-1))
    return np.concatenate(errors)


# -- compensation: does it generalise? -------------------------------------------------------

TRAIN_DISTANCES_M = (0.5, 1.0, 1.5, 2.0, 2.5)
TRAIN_TEMPS_C = (35.0, 39.0, 50.0)
TRAIN_VOX_STEPS_C = (25.0, 28.0, 31.0, 34.0, 37.0, 40.0)


@dataclass(frozen=True, eq=False)
class Generalisation:
    """Both methods fitted on one simulated sweep and scored on sweeps they never saw.

    train: distances 0.5-2.5 m, plates at 35, 39 and 50 C, VOx held at 25, 28, ..., 40 C;
    ours ("radiance") is fitted on all of it, the paper's method on the 39 C rows only (as
    the paper). tests: held-out distances (0.75, 1.25, 2.25, 3.0 m), held-out targets (45,
    60, 80 C), and VOx between and beyond the fitted steps (a 22 -> 43 C ramp).
    """

    train: SweepTable
    tests: dict[str, SweepTable]
    models: dict[str, CompensationModel]

    def table(self) -> list[dict[str, object]]:
        """RMSE, max |error| and mean error (C) per test set and method."""
        rows: list[dict[str, object]] = []
        for name, tab in self.tests.items():
            for method, model in self.models.items():
                o = overall(apply_to_table(model, tab).temp_c, tab)
                rows.append({"test": name, "method": method, **o})
        return rows


def _sweep(samples: int, seed: int, **changes: object) -> SweepTable:
    base = {
        "distances_m": TRAIN_DISTANCES_M,
        "plate_temps_c": TRAIN_TEMPS_C,
        "samples": samples,
        "seed": seed,
    }
    return simulate_sweep(SweepConfig(**{**base, **changes}))  # type: ignore[arg-type]


def training_sweep(samples: int = 600, seed: int = 0) -> SweepTable:
    """The sweep both methods are fitted on in :func:`compensation_generalisation` (the same
    rows for the same ``samples`` and ``seed``), for callers that only need a fitted model."""
    return _sweep(samples, seed * 10, vox_steps_c=TRAIN_VOX_STEPS_C)


def compensation_generalisation(samples: int = 600, seed: int = 0) -> Generalisation:
    """Simulate the training and held-out sweeps (``samples`` frames per distance and
    target) and fit both methods; see :class:`Generalisation`."""
    train = training_sweep(samples, seed)
    tests = {
        "held-out distances": _sweep(samples, seed * 10 + 1, distances_m=(0.75, 1.25, 2.25, 3.0)),
        "held-out targets": _sweep(samples, seed * 10 + 2, plate_temps_c=(45.0, 60.0, 80.0)),
        "VOx between/beyond": _sweep(samples, seed * 10 + 3, vox_min_c=22.0, vox_max_c=43.0),
    }
    models: dict[str, CompensationModel] = {
        "radiance": RadianceModel.fit(train),
        "paper": PaperModel.fit(train, reference_temp_c=39.0),
    }
    return Generalisation(train, tests, models)


# -- every camera: accuracy against truth, with and without the compensation -----------------


@dataclass(frozen=True)
class CameraAccuracy:
    """How one simulated rig measures a plate of known temperature.

    thermal, depth: the cameras; distance_m, vox_c: the plate's distance and the sensor's
    temperature (C); error_none_c, error_radiance_c: the plate's mean reading (its central
    thermal pixels, radiometry at each pixel's own distance) minus its true temperature,
    without compensation of the sensor and with ours fitted on a sweep of the same camera
    (C); registration_px: the median registration error at that distance (thermal px).
    """

    thermal: str
    depth: str
    distance_m: float
    vox_c: float
    error_none_c: float
    error_radiance_c: float
    registration_px: float


CHECK_DISTANCES_M = (0.5, 1.0, 2.0, 3.0)
CHECK_VOX_C = (26.0, 39.0)
CHECK_PLATE_C = 45.0  # between the fitted 39 and 50 C, at distances beyond and between


def camera_accuracy(
    thermal: str,
    depth: str = "848x480",
    distances_m: Sequence[float] = CHECK_DISTANCES_M,
    vox_c: Sequence[float] = CHECK_VOX_C,
    samples: int = 200,
    seed: int = 0,
) -> list[CameraAccuracy]:
    """:class:`CameraAccuracy` of a simulated camera pair at each distance and sensor
    temperature: the compensation is fitted on the training sweep of that camera
    (:func:`training_sweep`; a camera that tells no VOx temperature is fitted without it,
    and the pipeline compensates its frames at the model's reference), then a plate at
    :data:`CHECK_PLATE_C` is read by the pipeline at distances and sensor temperatures the
    sweep did not hold exactly."""
    from .pipeline import Pipeline, Settings
    from .radiometry import ZERO_C_IN_K
    from .sim import camera_pose, constant_fpa, plate_scene
    from .sim.cameras import depth_mode, rig_calibration, thermal_camera
    from .sim.protocols import plate_roi

    train = _sweep(samples, seed * 10, vox_steps_c=TRAIN_VOX_STEPS_C, thermal_camera=thermal)
    model = RadianceModel.fit(train)
    cal = rig_calibration(thermal_camera(thermal), depth_mode(depth))
    pipelines = {
        "none": Pipeline(Settings(), cal),
        "radiance": Pipeline(Settings(), cal, model=model),
    }
    out = []
    for d in distances_m:
        reg = registration_error(d, "reproject", seed, calibration=cal)
        for v in vox_c:
            rig = Rig.of_cameras(
                plate_scene(CHECK_PLATE_C),
                camera_pose(d),
                thermal,
                depth,
                fpa=constant_fpa(v + ZERO_C_IN_K),
                start_s=1.0,
                seed=seed,
            )
            roi = plate_roi(rig, 1)
            pair = rig.frame()
            errors = {
                name: float(np.nanmean(pipe.process(pair).temp_thermal_c[roi]) - CHECK_PLATE_C)
                for name, pipe in pipelines.items()
            }
            out.append(
                CameraAccuracy(
                    thermal, depth, d, v, errors["none"], errors["radiance"], reg.median_px
                )
            )
    return out
