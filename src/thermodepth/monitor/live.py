"""What a screen shows of a rig as it runs: its latest fused frame as an overlay picture (the
temperature on the depth image, on the rig's fixed colour scale, with hotspot boxes labelled
and ROIs outlined) and its thermal image, drawn fast (numpy and OpenCV, JPEG or PNG, no
matplotlib), and the trend of its readings over the last hour.

The depth grid of a frame is sampled on the rig's own thread (the registration is not shared
between threads), only while someone looks (:meth:`LiveView.wanted` in the last
:data:`WATCH_S`) and at most :data:`LIVE_HZ` a second; a picture is drawn once per frame and
size, however many screens ask for it.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..figures import display_range_c, overlay_rgb
from ..measure import DepthRangeRoi, PolygonRoi, RectRoi, Roi, hotspot_box_on_depth
from ..pipeline import FusedFrame
from ..plotting import temperature_rgb

LIVE_HZ = 4.0
WATCH_S = 5.0
TREND_EVERY_S = 10.0
TREND_S = 3600.0
JPEG_QUALITY = 85


def _bgr(rgb: NDArray[np.floating]) -> NDArray[np.uint8]:
    out: NDArray[np.uint8] = (np.clip(rgb, 0.0, 1.0) * 255 + 0.5).astype(np.uint8)
    return np.ascontiguousarray(out[..., ::-1])


def _label(img: NDArray[np.uint8], text: str, org: tuple[int, int], color: tuple[int, ...]) -> None:
    """Text on a dark box, as the overlay figure labels (OpenCV's Hershey font)."""
    font, scale, thick = cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1
    (w, h), base = cv2.getTextSize(text, font, scale, thick)
    x, y = org
    y = max(y, h + 2)
    cv2.rectangle(img, (x - 1, y - h - 2), (x + w + 1, y + base), (0, 0, 0), -1)
    cv2.putText(img, text, (x, y), font, scale, color, thick, cv2.LINE_AA)


def overlay_image(
    frame: FusedFrame, range_c: tuple[float, float], rois: list[Roi]
) -> NDArray[np.uint8]:
    """The overlay of a fused frame (its depth grid sampled), BGR uint8 (H, W, 3): the
    figure's image (:func:`~thermodepth.figures.overlay_rgb`), hotspot boxes (cyan when
    resolvable, yellow when too small to read true) labelled in C and metres, ROIs outlined
    in white with their names (a depth-range ROI has no outline)."""
    img = _bgr(overlay_rgb(frame, range_c))
    cal = frame.calibration
    for roi in rois:
        if isinstance(roi, RectRoi):
            cv2.rectangle(img, (roi.u0, roi.v0), (roi.u1 - 1, roi.v1 - 1), (255, 255, 255), 1)
            _label(img, roi.name, (roi.u0 + 2, roi.v0 + 14), (255, 255, 255))
        elif isinstance(roi, PolygonRoi):
            pts = np.round(np.asarray(roi.vertices)).astype(np.int32)
            cv2.polylines(img, [pts], True, (255, 255, 255), 1, cv2.LINE_AA)
            _label(img, roi.name, (int(pts[:, 0].min()) + 2, int(pts[:, 1].min()) + 14),
                   (255, 255, 255))  # fmt: skip
        else:
            assert isinstance(roi, DepthRangeRoi)
    for hs in frame.hotspots:
        box = hotspot_box_on_depth(
            hs, frame.z_thermal_m, cal.thermal, cal.depth, cal.thermal_from_depth
        )
        if box is None:
            continue
        u0, v0, u1, v1 = box
        color = (255, 255, 0) if hs.resolvable else (0, 255, 255)
        cv2.rectangle(img, (u0 - 2, v0 - 2), (u1 + 2, v1 + 2), color, 2)
        _label(img, f"{hs.max_c:.1f} C  {hs.distance_m:.2f} m", (u0, v0 - 6), color)
    return img


def thermal_image(
    frame: FusedFrame, range_c: tuple[float, float], scale: int = 4
) -> NDArray[np.uint8]:
    """The frame's temperatures on the thermal grid, BGR uint8, ``scale`` times larger
    (nearest: its pixels stay pixels); light grey where it has none."""
    t = frame.temp_thermal_c
    rgb = temperature_rgb(t, range_c).astype(np.float32) / 255.0
    rgb[~np.isfinite(t)] = 0.75
    return np.repeat(np.repeat(_bgr(rgb), scale, axis=0), scale, axis=1)


def encode(img: NDArray[np.uint8], kind: str, width: int | None = None) -> bytes:
    """An image as JPEG or PNG bytes, scaled to ``width`` pixels (keeping its shape)."""
    if width is not None and width < img.shape[1]:
        height = round(img.shape[0] * width / img.shape[1])
        img = np.asarray(cv2.resize(img, (width, height), interpolation=cv2.INTER_AREA))
    params = [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY] if kind == "jpeg" else []
    ok, data = cv2.imencode(".jpg" if kind == "jpeg" else ".png", img, params)
    assert ok
    return bytes(data)


@dataclass(frozen=True)
class Picture:
    """A live picture's bytes (JPEG or PNG) and the capture time of its frame (the thermal
    frame's, s: Unix time for a live rig; None: not known)."""

    data: bytes
    time_s: float | None


@dataclass
class Trend:
    """A rig's readings, one every :data:`TREND_EVERY_S` over the last :data:`TREND_S`: each
    ``{"time_s", "hottest_c", "rois": {NAME: max C or None}}``."""

    points: deque[dict[str, Any]] = field(
        default_factory=lambda: deque(maxlen=int(TREND_S / TREND_EVERY_S))
    )
    _at: float = float("-inf")

    def add(self, time_s: float, hottest_c: float | None, rois: dict[str, float | None]) -> None:
        """Readings at ``time_s``, kept if the last kept is TREND_EVERY_S old (monotonic)."""
        now = time.monotonic()
        if now - self._at >= TREND_EVERY_S:
            self._at = now
            self.points.append({"time_s": time_s, "hottest_c": hottest_c, "rois": rois})


@dataclass
class LiveView:
    """A rig's latest pictures and trend (module docstring). ``range_c``: the colour scale
    (None: fixed from the first frame with temperatures); ``rois``: outlined."""

    rois: list[Roi]
    range_c: tuple[float, float] | None = None
    frame: FusedFrame | None = None
    wanted_until: float = 0.0
    last_s: float = 0.0
    trend: Trend = field(default_factory=Trend)
    _cache: dict[tuple[int, str, int | None], Picture] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def fused(self, fused: FusedFrame) -> None:
        """A rig's fused frame (its own thread): kept for the screens while someone looks,
        its depth grid sampled here; its readings into the trend every TREND_EVERY_S."""
        now = time.monotonic()
        if not fused.in_ffc:
            hot = fused.hotspots[0].max_c if fused.hotspots else None
            rois = {r.name: (r.max_c if r.n else None) for r in fused.rois}
            self.trend.add(fused.thermal_time_s, hot, rois)
        if now > self.wanted_until or now - self.last_s < 1.0 / LIVE_HZ:
            return
        self.last_s = now
        _ = fused.on_depth
        if self.range_c is None and np.isfinite(fused.temp_thermal_c).any():
            self.range_c = display_range_c(fused.temp_depth_c)
        with self._lock:
            self.frame = fused
            self._cache.clear()

    def wanted(self) -> None:
        """Someone looks: keep the pictures coming for WATCH_S."""
        self.wanted_until = time.monotonic() + WATCH_S

    def picture(self, what: str, width: int | None = None) -> Picture | None:
        """The latest ``overlay`` (JPEG) or ``thermal`` (PNG) picture, None before the first
        frame someone looked at."""
        self.wanted()
        with self._lock:
            frame = self.frame
            key = (-1 if frame is None else frame.index, what, width)
            cached = self._cache.get(key)
        if frame is None or cached is not None:
            return cached
        range_c = self.range_c or (15.0, 80.0)
        if what == "overlay":
            data = encode(overlay_image(frame, range_c, self.rois), "jpeg", width)
        else:
            data = encode(thermal_image(frame, range_c), "png", width)
        picture = Picture(data, frame.thermal_time_s)
        with self._lock:
            if self.frame is frame:
                self._cache[key] = picture
        return picture
