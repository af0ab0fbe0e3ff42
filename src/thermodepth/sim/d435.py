"""The virtual D435: ray-cast depth with the stereo noise model, range limits and the
stereo shadow, in Z16 units; an optional infrared image for calibration targets.

Noise: sigma_z = z^2 * subpixel / (fx * baseline) (Intel's depth RMS model: 50 mm baseline,
subpixel ~0.08). Invalid (0) outside 0.2-10 m and where the right imager cannot see what the
left one (the depth origin) sees: the band left of a near object's left edge, as wide as the
disparity step fx * B * (1/z_near - 1/z_far) (the black regions of the paper's Fig. 12b).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class DepthCameraModel:
    """Depth camera parameters (defaults: D435 datasheet / Intel's tuning guide values).

    subpixel: stereo matching precision in pixels; baseline_m: between the imagers;
    min_z_m / max_z_m: valid range; fps: frame rate; noise / stereo_shadow: switches;
    ir_gain / ir_noise_dn: infrared image brightness for albedo 1 and its noise (8-bit DN);
    ir_supersample: rays per pixel side for the infrared image (anti-aliasing).
    """

    subpixel: float = 0.08
    baseline_m: float = 0.050
    min_z_m: float = 0.2
    max_z_m: float = 10.0
    fps: float = 30.0
    noise: bool = True
    stereo_shadow: bool = True
    ir_gain: float = 230.0
    ir_noise_dn: float = 1.5
    ir_supersample: int = 3


def depth_sigma_m(
    z_m: FloatArray | float, fx: float, model: DepthCameraModel
) -> FloatArray | float:
    """RMS depth error (m) at depth ``z_m``: z^2 * subpixel / (fx * baseline)."""
    return np.square(z_m) * model.subpixel / (fx * model.baseline_m)


@numba.njit(parallel=True, cache=True)
def _shadow(z, fx, baseline, out):  # pragma: no cover - JIT
    h, w = z.shape
    for r in numba.prange(h):
        # scan right to left: a pixel is hidden from the right imager when its position there
        # does not stay left of everything to its right (ordering constraint)
        min_right = np.inf
        for c in range(w - 1, -1, -1):
            zc = z[r, c]
            out[r, c] = False
            if not (zc > 0.0 and zc < np.inf):
                continue
            ur = c - fx * baseline / zc
            if ur >= min_right:
                out[r, c] = True
            else:
                min_right = ur


def stereo_shadow(z_m: FloatArray, fx: float, baseline_m: float) -> NDArray[np.bool_]:
    """Pixels of the left (depth) view that the right imager, ``baseline_m`` to the right,
    cannot see. ``z_m`` (H, W) true depth; inf or NaN = nothing there."""
    out = np.empty(z_m.shape, dtype=np.bool_)
    _shadow(np.ascontiguousarray(z_m, dtype=np.float64), float(fx), float(baseline_m), out)
    return out


@numba.njit(parallel=True, cache=True)
def _to_units(z, noise, k_sigma, min_z, max_z, scale, shadow, out):  # pragma: no cover - JIT
    h, w = z.shape
    for r in numba.prange(h):
        for c in range(w):
            zt = z[r, c]
            zn = zt + noise[r, c] * k_sigma * zt * zt
            if shadow[r, c] or not (zn >= min_z and zn <= max_z):
                out[r, c] = 0
            else:
                out[r, c] = min(np.rint(zn / scale), 65535.0)


def depth_units(
    z_true_m: FloatArray,
    fx: float,
    depth_scale_m: float,
    model: DepthCameraModel,
    rng: np.random.Generator,
    shadow: NDArray[np.bool_] | None = None,
) -> NDArray[np.uint16]:
    """A Z16 frame: noisy depth in units of ``depth_scale_m``, 0 where invalid.

    ``shadow`` (precomputed :func:`stereo_shadow`, it depends only on the geometry) is
    invalidated when the model asks for it.
    """
    if model.noise:
        noise = rng.standard_normal(z_true_m.shape, dtype=np.float32)
    else:
        noise = np.zeros(z_true_m.shape, dtype=np.float32)
    if shadow is None or not model.stereo_shadow:
        shadow = np.zeros(z_true_m.shape, dtype=np.bool_)
    out = np.empty(z_true_m.shape, dtype=np.uint16)
    k_sigma = float(depth_sigma_m(1.0, fx, model))  # sigma_z = k_sigma z^2
    _to_units(
        np.ascontiguousarray(z_true_m),
        noise,
        k_sigma,
        model.min_z_m,
        model.max_z_m,
        depth_scale_m,
        shadow,
        out,
    )
    return out


@numba.njit(parallel=True, cache=True)
def _to_dn(albedo, gain, noise, noise_dn, out):  # pragma: no cover - JIT
    # rint(albedo gain + noise noise_dn) clipped to 0..255, as numpy's whole-array passes
    h, w = albedo.shape
    for r in numba.prange(h):
        for c in range(w):
            pix = albedo[r, c] * gain
            if noise.shape[0]:
                pix = pix + noise[r, c] * noise_dn
            out[r, c] = min(max(np.rint(pix), 0.0), 255.0)


def ir_image(
    albedo: FloatArray, model: DepthCameraModel, rng: np.random.Generator
) -> NDArray[np.uint8]:
    """8-bit infrared image from each pixel's near-IR albedo (H, W) (the mean over its
    sub-rays; emitter off, even illumination), with read noise."""
    albedo = np.ascontiguousarray(albedo, np.float64)
    noise = rng.standard_normal(albedo.shape) if model.noise else np.empty((0, 0))
    out = np.empty(albedo.shape, np.uint8)
    _to_dn(albedo, float(model.ir_gain), noise, float(model.ir_noise_dn), out)
    return out
