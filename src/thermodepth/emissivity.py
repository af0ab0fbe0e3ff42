"""Emissivity measured with a reference emitter (the method of ASTM E1933).

A piece of tape or paint of known emissivity (the *reference*) sits on or beside the
*target*, at the same temperature. The reference, read at its known emissivity, gives the true
temperature; the target's emissivity is the one at which the target reads that same
temperature.

Per frame:

1. the pipeline reads the reference ROI at its emissivity (and at that emissivity minus and
   plus its stated tolerance): its mean is the true temperature T;
2. for every thermal pixel, the emissivity at which the pipeline's own radiometry (the
   settings' model and compensation, the pixel's own distance and air path, the target's
   reflected temperature: its own, its reflector's reading this frame, else the settings')
   gives T from the pixel's value is found by bisection over (0.01, 1];
3. those emissivities are averaged over the target ROI as its temperatures would be (the
   registration's sampling onto the depth grid).

Over N frames: the estimate is the mean of the frames' values. Its standard uncertainty
(k = 1) combines, in quadrature, the frames' spread (their standard deviation over sqrt(N))
and the reference's stated tolerance, taken as a rectangular distribution of half-width
``tolerance`` (standard uncertainty tolerance / sqrt(3)) propagated through the solve by its
sensitivity (the change of the estimate between the reference read at emissivity minus and
plus the tolerance, over twice the tolerance). The reflected temperature's own uncertainty is
not included: measure it (a reflector ROI) rather than guess it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from .calibration import Calibration
from .errors import FieldError, InputError
from .frames import FramePair
from .measure import roi_region
from .pipeline import FusedFrame, Pipeline, RoiSettings, Settings
from .registration import Regions

LOWEST = 0.01
"""The lowest emissivity the solve looks for (a polished metal's is some 0.02)."""
BISECTIONS = 24
"""Halvings of (0.01, 1]: the solve's resolution, 6e-8, is far below any estimate's
uncertainty."""


@dataclass(frozen=True)
class EmissivityEstimate:
    """The target's emissivity (``emissivity``) and its standard uncertainty (k = 1,
    ``uncertainty``; module docstring) with its two parts (``from_frames``,
    ``from_reference``); ``frames``: frames used; ``frame_sd``: the spread of their values;
    ``temp_c``: the reference's mean temperature (C); ``per_frame``: each frame's value."""

    emissivity: float
    uncertainty: float
    from_frames: float
    from_reference: float
    frames: int
    frame_sd: float
    temp_c: float
    per_frame: tuple[float, ...]

    def line(self, target: str) -> str:
        """The result in one line for people."""
        return (
            f"{target}: emissivity {self.emissivity:.3f} +- {self.uncertainty:.3f} (k=1; "
            f"frames {self.from_frames:.3f}, reference tolerance {self.from_reference:.3f}) "
            f"at {self.temp_c:.1f} C over {self.frames} frame{'s' * (self.frames != 1)}"
        )


def check_reference(emissivity: float, tolerance: float) -> None:
    """FieldError unless 0 < ``emissivity`` <= 1 and 0 <= ``tolerance`` < ``emissivity``."""
    if not 0 < emissivity <= 1:
        raise FieldError("reference_emissivity", f"{emissivity:g} is outside (0, 1]")
    if not 0 <= tolerance < emissivity:
        raise FieldError("tolerance", f"{tolerance:g}: expected 0 <= tolerance < the emissivity")


def _names(settings: Settings, reference: str, target: str) -> dict[str, RoiSettings]:
    by_name = {r.name: r for r in settings.rois}
    for option, name in (("reference", reference), ("target", target)):
        if name not in by_name:
            raise FieldError(
                option, f"{name!r} is no ROI of {settings.where} ({', '.join(by_name) or 'none'})"
            )
    if reference == target:
        raise FieldError("target", "the target must be another ROI than the reference")
    return by_name


def solver_settings(
    settings: Settings, reference: str, emissivities: Iterable[float]
) -> tuple[Settings, list[str]]:
    """Settings that read the reference ROI at each of ``emissivities`` (one copy each, named
    ``REFERENCE@E``) beside the other ROIs (severity classes and alarms left out), and the
    copies' names."""
    rois, copies = [], []
    for r in settings.rois:
        if r.name != reference:
            swap = (
                [f"{reference}@{e:g}" for e in emissivities] if reference in r.reflects_for else []
            )
            names = [n for n in r.reflects_for if n != reference] + swap
            rois.append(r.model_copy(update={"severity": None, "reflects_for": names}))
            continue
        for e in emissivities:
            name = f"{reference}@{e:g}"
            copies.append(name)
            update = {"name": name, "emissivity": e, "material": None, "severity": None}
            rois.append(r.model_copy(update=update))
    plain = Settings(
        calibration=settings.calibration,
        compensation=settings.compensation,
        radiometry=settings.radiometry,
        registration=settings.registration,
        fallback_distance_m=settings.fallback_distance_m,
        rois=rois,
    )
    return plain, copies


def emissivity_map(
    pipeline: Pipeline, pair: FramePair, temp_c: float, reflected_c: float | None
) -> tuple[NDArray[np.float32], NDArray[np.uint8]]:
    """Each thermal pixel's emissivity (h, w) at which the pipeline's radiometry reads
    ``temp_c`` (C) from its value at its own distance, with the reflected temperature
    ``reflected_c`` (C; None: the settings'); NaN where none in (0.01, 1] does (the reading
    does not change sign across it: a pixel of another temperature, or one at the reflected
    temperature). Also the pixels' flags."""
    radiometry = pipeline.radiometry_of(pair)
    near = pipeline.registration.depth_to_thermal(pair.depth)
    distance, _ = pipeline.distances(near.range_m)
    conditions = radiometry.conditions
    if reflected_c is not None:
        conditions = conditions.replace(reflected_temp_c=reflected_c)
    vox_c = pair.telemetry.fpa_temp_c

    def miss(emissivity: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.uint8]]:
        own = replace(radiometry, conditions=conditions.replace(emissivity=emissivity))
        temp, flags = pipeline.temperatures(pair.thermal, vox_c, distance, own)
        return temp.astype(np.float64) - temp_c, flags

    shape = pair.thermal.shape
    lo, hi = np.full(shape, LOWEST), np.ones(shape)
    f_lo, _ = miss(lo)
    f_hi, flags = miss(hi)
    with np.errstate(invalid="ignore"):
        bracketed = np.sign(f_lo) * np.sign(f_hi) <= 0
    for _ in range(BISECTIONS):
        mid = (lo + hi) / 2
        f_mid, _ = miss(mid)
        with np.errstate(invalid="ignore"):
            same = np.sign(f_mid) == np.sign(f_lo)
        lo, f_lo = np.where(same, mid, lo), np.where(same, f_mid, f_lo)
        hi = np.where(same, hi, mid)
    found = np.where(bracketed, (lo + hi) / 2, np.nan)
    return found.astype(np.float32), flags


def roi_mean(pipeline: Pipeline, pair: FramePair, values: NDArray[np.float32], roi: str) -> float:
    """The mean of thermal-grid ``values`` (h, w) over an ROI of the pipeline's settings, as
    its temperatures are sampled (the registration onto the depth grid); NaN when no pixel of
    it has a finite value."""
    cal = pipeline.calibration
    index = [r.name for r in pipeline.settings.rois].index(roi)
    region = roi_region(pipeline.rois[index], cal.depth.shape, cal.depth_scale_m)
    regions = Regions([region], cal.depth.height)
    sums = regions.row_sums()
    pipeline.registration.thermal_to_depth(
        pair.depth, values, pipeline.settings.registration.interpolation, regions=sums
    )
    m = Regions.moments(sums)[0]
    return m.mean if m.n else math.nan


def _mean_c(frame: FusedFrame, name: str) -> float:
    r = next(r for r in frame.rois if r.name == name)
    return r.mean_c if r.n else math.nan


def estimate_emissivity(
    settings: Settings,
    calibration: Calibration,
    pairs: Iterable[FramePair],
    reference: str,
    target: str,
    reference_emissivity: float,
    tolerance: float = 0.02,
) -> EmissivityEstimate:
    """The target ROI's emissivity from a reference ROI of ``reference_emissivity`` (its
    stated ``tolerance``, +-) over the frames of ``pairs`` (module docstring; frames taken
    while the shutter is closed are skipped). InputError when no frame gives a value."""
    check_reference(reference_emissivity, tolerance)
    by_name = _names(settings, reference, target)
    low, high = reference_emissivity - tolerance, min(1.0, reference_emissivity + tolerance)
    plain, (at, at_low, at_high) = solver_settings(
        settings, reference, (reference_emissivity, low, high)
    )
    pipeline = Pipeline(plain, calibration)
    reflector = plain.reflector_of(target)
    own_reflected = by_name[target].reflected_temp_c
    values: list[tuple[float, float, float, float]] = []
    for pair in pairs:
        if pair.telemetry.in_ffc:
            continue
        frame = pipeline.process(pair)
        reflected_c = own_reflected
        if reflector is not None and np.isfinite(_mean_c(frame, reflector)):
            reflected_c = _mean_c(frame, reflector)
        solved = []
        for copy in (at, at_low, at_high):
            temp_c = _mean_c(frame, copy)
            eps = (
                emissivity_map(pipeline, pair, temp_c, reflected_c)[0]
                if np.isfinite(temp_c)
                else None
            )
            solved.append(math.nan if eps is None else roi_mean(pipeline, pair, eps, target))
        if np.isfinite(solved[0]):
            values.append((solved[0], solved[1], solved[2], _mean_c(frame, at)))
    if not values:
        raise InputError(
            f"no frame gives {target!r} an emissivity: is it at the reference's temperature, "
            "and warmer or cooler than what it reflects?"
        )
    v = np.array(values)
    n = len(v)
    mean = float(v[:, 0].mean())
    sd = float(v[:, 0].std(ddof=1)) if n > 1 else 0.0
    sensitivity = float(np.nanmean(v[:, 2] - v[:, 1])) / (high - low) if high > low else 0.0
    from_reference = abs(sensitivity) * tolerance / math.sqrt(3)
    from_frames = sd / math.sqrt(n)
    return EmissivityEstimate(
        mean,
        math.hypot(from_frames, from_reference),
        from_frames,
        from_reference,
        n,
        sd,
        float(v[:, 3].mean()),
        tuple(float(x) for x in v[:, 0]),
    )
