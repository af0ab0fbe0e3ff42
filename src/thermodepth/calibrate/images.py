"""Calibration images: reading them (8- or 16-bit PNG, TIFF, JPEG or ``.npy``), stretching
low-contrast thermal images, and the upscale small images get before detection."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..palettes import NotFalseColourError, to_scalar

IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".npy", ".jpg", ".jpeg", ".bmp", ".pgm")


def load_image(path: str | Path, thermal: bool = False) -> NDArray[Any]:
    """A 2-D image (H, W) from PNG, TIFF, JPEG, BMP, PGM or ``.npy``, in its own dtype (uint8,
    uint16 counts, float). Raises InputError naming the file when it cannot be read or is not
    one image.

    Colour images: a depth camera's (``thermal`` False) become grey (luminance); a thermal
    camera's are false-colour exports of viewer tools, turned back into the palette's levels
    (float32, 0..255: :func:`~thermodepth.palettes.to_scalar`), and refused, naming the file,
    when their colours are no palette's. Raw counts (16-bit PNG, ``.npy``) keep every level
    the camera measured and calibrate best.
    """
    p = Path(path)
    img = _read(p)
    if img.ndim == 3:
        colour = np.ascontiguousarray(img[..., :3])
        if thermal and colour.dtype == np.uint8:  # viewers save false colour in 8 bits
            try:
                return to_scalar(colour).levels
            except NotFalseColourError as exc:
                raise InputError(f"{p}: not a thermal image: {exc}") from None
        img = cv2.cvtColor(colour, cv2.COLOR_RGB2GRAY)
    numeric = np.issubdtype(img.dtype, np.integer) or np.issubdtype(img.dtype, np.floating)
    if img.ndim != 2 or not numeric:
        raise InputError(f"{p}: expected a 2-D numeric image, got {img.dtype} {img.shape}")
    return img


def _read(p: Path) -> NDArray[Any]:
    """The array an image file holds: (H, W), or (H, W, 3 or 4) RGB(A) for colour."""
    if p.suffix.lower() == ".npy":
        try:
            img = np.load(p, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InputError(f"{p}: unreadable .npy ({str(exc).splitlines()[0]})") from None
        if img.ndim == 3 and img.shape[2] == 1:
            img = img[..., 0]
        if img.ndim == 3 and not (img.shape[2] in (3, 4) and img.dtype in (np.uint8, np.uint16)):
            raise InputError(f"{p}: expected a 2-D numeric image, got {img.dtype} {img.shape}")
        return np.asarray(img)
    try:
        data = np.frombuffer(p.read_bytes(), dtype=np.uint8)
    except OSError as exc:
        raise InputError(f"{p}: unreadable ({exc.strerror or exc})") from None
    # a truncated file is ours to report, in one line: OpenCV's own warning would be a second
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    try:
        raw = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    finally:
        cv2.utils.logging.setLogLevel(level)
    if raw is None or raw.size == 0:
        raise InputError(f"{p}: unreadable (not an image OpenCV can decode)")
    img = np.asarray(raw)
    return img[..., :3][..., ::-1] if img.ndim == 3 else img  # OpenCV's BGR(A): RGB


def stretch_to_unit(
    image: NDArray[Any], low_pct: float = 1.0, high_pct: float = 99.5
) -> NDArray[np.float32] | None:
    """Affine map of an image to 0..255 by its percentiles (float32, not clipped).

    The ``low_pct`` percentile maps to 0 and ``high_pct`` to 255: robust to hot or dead pixels
    and to a 14-bit thermal image whose board spans a few hundred counts. Values outside the
    range are kept (clipping happens only for 8-bit detection), so corner refinement sees
    the image's real gradients. NaNs become the median. None when the image is flat.
    """
    f = image.astype(np.float32)
    if np.issubdtype(image.dtype, np.floating):
        finite = np.isfinite(f)
        if not finite.any():
            return None
        f = np.where(finite, f, np.median(f[finite])).astype(np.float32)
    lo, hi = np.percentile(f, [low_pct, high_pct])
    if not hi > lo:
        lo, hi = float(f.min()), float(f.max())
        if not hi > lo:
            return None
    return ((f - lo) * (255.0 / (hi - lo))).astype(np.float32)


def plain_grey(image: NDArray[Any]) -> NDArray[np.uint8]:
    """The 8-bit grey image a user hands OpenCV: uint8 as it is, anything else stretched
    from its minimum to its maximum (NaN as the minimum)."""
    if image.dtype == np.uint8:
        return image
    f = np.asarray(image, dtype=np.float64)
    finite = np.isfinite(f)
    if not finite.any():
        return np.zeros(f.shape, np.uint8)
    lo, hi = f[finite].min(), f[finite].max()
    scaled = (np.where(finite, f, lo) - lo) * (255.0 / max(hi - lo, 1e-12))
    return np.clip(np.rint(scaled), 0, 255).astype(np.uint8)


def upscale_factor(shape: tuple[int, ...]) -> int:
    """Integer upscale before detection: to at least 480 px high (160x120 -> 4x).

    OpenCV's detectors look for quads and blobs a few pixels wide; a Lepton sees a 3 cm square
    at 0.7 m as 6 px. Images 480 px high or more are left as they are.
    """
    return max(1, min(8, math.ceil(480 / shape[0])))
