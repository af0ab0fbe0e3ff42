"""What a screen shows of a rig as it runs: its latest fused frame as an overlay picture (the
temperature on the depth image, on the rig's fixed colour scale, with hotspot boxes labelled
and ROIs outlined, in red those whose alarm is raised) and its thermal image, drawn fast
(numpy and OpenCV, JPEG or PNG, no matplotlib), and the trend of its readings over the last
hour.

The depth grid of a frame is sampled on the rig's own thread (the registration is not shared
between threads), only while someone looks (:meth:`LiveView.wanted` in the last
:data:`WATCH_S`) and at most :data:`LIVE_HZ` a second, or as often as a video stream that
plays asks (:meth:`LiveView.video`); a picture is drawn once per frame and size, however
many screens ask for it, a video frame once per frame and view, however many streams.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..figures import ALARM_RGB, alarm_rois, display_range_c, overlay_rgb, roi_outlines
from ..isotherms import ISOTHERM_RGB, IsothermArea
from ..lines import LineProfile
from ..measure import DepthRangeRoi, PolygonRoi, Roi, hotspot_box_on_depth
from ..pipeline import FusedFrame
from ..plotting import temperature_rgb

if TYPE_CHECKING:
    from ..alarms import AlarmTracker

LIVE_HZ = 4.0
WATCH_S = 5.0
TREND_EVERY_S = 10.0
TREND_S = 3600.0
JPEG_QUALITY = 85


def _bgr(rgb: NDArray[np.floating]) -> NDArray[np.uint8]:
    out: NDArray[np.uint8] = (np.clip(rgb, 0.0, 1.0) * 255 + 0.5).astype(np.uint8)
    return np.ascontiguousarray(out[..., ::-1])


FONT, FONT_SCALE, FONT_THICK = cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1
WHITE, BLACK = (255, 255, 255), (0, 0, 0)
ALARM_BGR = tuple(round(255 * c) for c in ALARM_RGB[::-1])
ISOTHERM_BGR = ISOTHERM_RGB[::-1]
Rect = tuple[int, int, int, int]
"""A rectangle of pixels (x0, y0, x1, y1), both ends inside."""


def _label_size(text: str) -> tuple[int, int]:
    """The width and height (pixels) of a label's dark box (:func:`_label`)."""
    (w, h), base = cv2.getTextSize(text, FONT, FONT_SCALE, FONT_THICK)
    return w + 2, h + base + 2


def _label(
    img: NDArray[np.uint8],
    text: str,
    at: tuple[int, int],
    color: tuple[int, ...],
    back: tuple[int, ...] = BLACK,
) -> Rect:
    """Text on a box of ``back`` (black: as the overlay figure labels), the box's top left
    corner at ``at``, kept inside the image (OpenCV's Hershey font); returns the box."""
    th = cv2.getTextSize(text, FONT, FONT_SCALE, FONT_THICK)[0][1]
    w, h = _label_size(text)
    x = min(max(at[0], 0), max(img.shape[1] - w, 0))
    y = min(max(at[1], 0), max(img.shape[0] - h, 0))
    cv2.rectangle(img, (x, y), (x + w - 1, y + h - 1), back, -1)
    cv2.putText(img, text, (x + 1, y + 1 + th), FONT, FONT_SCALE, color, FONT_THICK, cv2.LINE_AA)
    return x, y, x + w - 1, y + h - 1


def label_place(
    box: Rect, size: tuple[int, int], shape: tuple[int, ...], gap: int = 3
) -> tuple[int, int]:
    """Where a label of ``size`` (w, h) goes beside ``box`` (its outer pixels) so that the box
    never covers it: its top left corner ``gap`` pixels above the box (still apart on a
    picture scaled to half), else below it (at the image's top edge), else to its right or
    left (a box as tall as the image), kept inside an image of ``shape`` (H, W, ...); over
    the box's top left corner only when none of these has room."""
    w, h = size
    x0, y0, x1, y1 = box
    height, width = shape[0], shape[1]
    if y0 - gap - h >= 0:
        return min(max(x0, 0), max(width - w, 0)), y0 - gap - h
    if y1 + gap + h < height:
        return min(max(x0, 0), max(width - w, 0)), y1 + gap + 1
    y = min(max(y0, 0), max(height - h, 0))
    if x1 + gap + w < width:
        return x1 + gap + 1, y
    if x0 - gap - w >= 0:
        return x0 - gap - w, y
    return max(x0, 0), y


def draw_hotspot(img: NDArray[np.uint8], box: Rect, text: str, color: tuple[int, ...]) -> Rect:
    """A hotspot's box around the pixels ``box`` (2 px off, 2 px wide) and its label beside
    it (:func:`label_place`); returns the label's box."""
    u0, v0, u1, v1 = box
    cv2.rectangle(img, (u0 - 2, v0 - 2), (u1 + 2, v1 + 2), color, 2)
    # a line of thickness 2 reaches one pixel beyond its corners on each side
    outer = (u0 - 3, v0 - 3, u1 + 3, v1 + 3)
    return _label(img, text, label_place(outer, _label_size(text), img.shape), color)


def overlay_image(
    frame: FusedFrame,
    range_c: tuple[float, float],
    rois: list[Roi],
    marked: Mapping[str, str] | None = None,
) -> NDArray[np.uint8]:
    """The overlay of a fused frame (its depth grid sampled), BGR uint8 (H, W, 3): the
    figure's image (:func:`~thermodepth.figures.overlay_rgb`), hotspot boxes (cyan when
    resolvable, yellow when too small to read true) labelled in C and metres above the box
    (below at the top edge: never under it), ROIs outlined in white with their names (a
    depth-range ROI only when marked); those in ``marked`` (name: the level of a raised
    rule that watches it) in red, thicker, labelled ``NAME: LEVEL``."""
    img = _bgr(overlay_rgb(frame, range_c))
    cal = frame.calibration
    marked = marked or {}
    for roi in rois:
        alarm = roi.name in marked
        if isinstance(roi, DepthRangeRoi) and not alarm:
            continue
        outlines = roi_outlines(roi, frame.depth_m)
        if not outlines:
            continue
        smooth = cv2.LINE_AA if isinstance(roi, PolygonRoi) else cv2.LINE_8  # pixels crisp
        cv2.polylines(img, outlines, True, ALARM_BGR if alarm else WHITE, 3 if alarm else 1,
                      smooth)  # fmt: skip
        u, v = min((tuple(p) for pts in outlines for p in pts), key=lambda p: (p[1], p[0]))
        if alarm:
            _label(
                img,
                f"{roi.name}: {marked[roi.name].upper()}",
                (int(u) + 3, int(v) + 3),
                WHITE,
                ALARM_BGR,
            )
        else:
            _label(img, roi.name, (int(u) + 2, int(v) + 2), WHITE)
    for hs in frame.hotspots:
        box = hotspot_box_on_depth(
            hs, frame.z_thermal_m, cal.thermal, cal.depth, cal.thermal_from_depth
        )
        if box is None:
            continue
        color = (255, 255, 0) if hs.resolvable else (0, 255, 255)
        draw_hotspot(img, box, f"{hs.max_c:.1f} C  {hs.distance_m:.2f} m", color)
    draw_lines_and_isotherms(img, frame)
    return img


def draw_lines_and_isotherms(img: NDArray[np.uint8], frame: FusedFrame) -> None:
    """Each line's hottest point (a ring) labelled with its temperature and where it is
    along the line (m) of its length, and each isotherm's area beside its band's top
    (the lines themselves are outlined as ROIs, the bands drawn in the image)."""
    for p in frame.lines:
        if p.max_px is None:
            continue
        u, v = p.max_px
        cv2.circle(img, (u, v), 5, WHITE, 2, cv2.LINE_AA)
        text = f"{p.max_c:.1f} C at {p.max_at_m:.2f} / {p.length_m:.2f} m"
        _label(img, text, label_place((u - 6, v - 6, u + 6, v + 6), _label_size(text),
                                      img.shape), WHITE)  # fmt: skip
    width = img.shape[1]
    for iso in frame.isotherms:
        if iso.n == 0:
            continue
        v, u = divmod(int(iso.pixels[0]), width)  # its topmost pixel, raster order
        text = f"{iso.name}: {iso.area_cm2:.0f} cm2"
        _label(img, text, label_place((u, v, u, v), _label_size(text), img.shape), ISOTHERM_BGR)


LEGEND_PX = 150
"""The width of the legend beside a framed picture (:func:`framed`)."""
TITLE_PX = 26


def framed(
    img: NDArray[np.uint8], range_c: tuple[float, float], title: str, reasons: bool = True
) -> NDArray[np.uint8]:
    """A picture with what it needs to be read alone (an event's snapshot, a video stream):
    ``title`` above it, and beside it the colour scale over ``range_c`` (C) with its ticks
    and (``reasons``: an overlay's) the tints of the pixels without a temperature
    (:data:`~thermodepth.figures.NO_TEMPERATURE`), BGR uint8, :data:`TITLE_PX` taller and
    :data:`LEGEND_PX` wider than ``img``."""
    from ..figures import NO_TEMPERATURE

    h, w = img.shape[:2]
    out = np.full((h + TITLE_PX, w + LEGEND_PX, 3), 32, np.uint8)
    out[TITLE_PX:, :w] = img
    cv2.putText(out, title, (6, TITLE_PX - 8), FONT, FONT_SCALE, WHITE, FONT_THICK, cv2.LINE_AA)
    lo, hi = range_c
    bar_top, bar_h = TITLE_PX + 10, max(40, h - 160)
    x0 = w + 12
    temps = np.linspace(hi, lo, bar_h)[:, None].repeat(18, axis=1)
    out[bar_top : bar_top + bar_h, x0 : x0 + 18] = _bgr(temperature_rgb(temps, range_c) / 255.0)
    for k in range(5):
        t = hi - k * (hi - lo) / 4
        y = bar_top + round(k * (bar_h - 1) / 4)
        cv2.line(out, (x0 + 18, y), (x0 + 22, y), WHITE, 1)
        cv2.putText(out, f"{t:.0f} C", (x0 + 26, y + 5), FONT, 0.45, WHITE, 1, cv2.LINE_AA)
    y = bar_top + bar_h + 18
    for _, words, tint, striped in NO_TEMPERATURE if reasons else ():
        swatch = np.zeros((12, 18, 3), np.uint8)
        swatch[:] = _bgr(np.asarray(tint, np.float32))
        if striped:
            v, u = np.mgrid[:12, :18]
            swatch[((u + v) // 4) % 2 == 1] = 90
        out[y - 10 : y + 2, x0 : x0 + 18] = swatch
        for i, line in enumerate(_wrapped(words, 14)):
            cv2.putText(out, line, (x0 + 24, y + 14 * i), FONT, 0.38, WHITE, 1, cv2.LINE_AA)
        y += 14 * len(_wrapped(words, 14)) + 10
    return out


def _wrapped(text: str, width: int) -> list[str]:
    lines: list[str] = []
    for word in text.split():
        if lines and len(lines[-1]) + 1 + len(word) <= width:
            lines[-1] += f" {word}"
        else:
            lines.append(word)
    return lines


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


VIEWS = ("overlay", "thermal")
"""What a video stream shows (:meth:`LiveView.video`)."""


@dataclass(frozen=True)
class VideoFrame:
    """A video stream's picture: ``image`` (BGR uint8, H x W x 3; a monitor's is framed: a
    title with the frame's time, the colour scale beside it) and its frame's capture time (s,
    as :class:`Picture`'s)."""

    image: NDArray[np.uint8]
    time_s: float | None

    @cached_property
    def jpeg(self) -> bytes:
        """The image as JPEG, encoded once however many streams send it."""
        return encode(self.image, "jpeg")


def video_size(
    depth_wh: tuple[int, int], thermal_wh: tuple[int, int], view: str
) -> tuple[int, int]:
    """The size (W, H, pixels) of a video stream's pictures for cameras of these sizes: the
    overlay on the depth grid, or the thermal image 4 times larger, each with its title and
    colour scale (:func:`framed`)."""
    w, h = depth_wh if view == "overlay" else (4 * thermal_wh[0], 4 * thermal_wh[1])
    return w + LEGEND_PX, h + TITLE_PX


def time_label(time_s: float | None) -> str:
    """A frame's capture time as a picture's title says it: local wall-clock time for a
    live rig's (Unix) time, else seconds."""
    if time_s is None:
        return ""
    if time_s > 1e9:  # Unix time: a live rig, or a recording replayed at its pace
        return time.strftime("%Y-%m-%d %H:%M:%S %Z", time.localtime(time_s))
    return f"{time_s:.2f} s"


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
    (None: fixed from the first frame with temperatures); ``rois``: outlined, in red those
    whose alarm rules were raised at ``frame`` (``marked``)."""

    rois: list[Roi]
    range_c: tuple[float, float] | None = None
    frame: FusedFrame | None = None
    marked: dict[str, str] = field(default_factory=dict)
    last_s: float = 0.0
    trend: Trend = field(default_factory=Trend)
    _wanted: dict[float, float] = field(default_factory=dict)  # a rate (Hz): until when
    _cache: dict[tuple[int, str, int | None], Picture] = field(default_factory=dict)
    _videos: dict[str, VideoFrame] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _shapes: tuple[list[LineProfile], list[IsothermArea]] = ([], [])  # the latest measured

    def lines(self) -> dict[str, Any]:
        """The latest frame's line profiles and isotherm areas (plain data: a dashboard's
        chart), as its JSON line has them."""
        lines, isotherms = self._shapes
        return {
            "lines": [p.as_dict() for p in lines],
            "isotherms": [i.as_dict() for i in isotherms],
        }

    def fused(self, fused: FusedFrame, alarms: AlarmTracker | None = None) -> None:
        """A rig's fused frame (its own thread): kept for the screens while someone looks,
        its depth grid sampled here, with the ROIs of the rules ``alarms`` has raised now;
        its readings into the trend every TREND_EVERY_S."""
        now = time.monotonic()
        if not fused.in_ffc:
            hot = fused.hotspots[0].max_c if fused.hotspots else None
            rois = {r.name: (r.max_c if r.n else None) for r in fused.rois}
            self.trend.add(fused.thermal_time_s, hot, rois)
            self._shapes = (fused.lines, fused.isotherms)  # one reference: no copy per frame
        with self._lock:
            rates = [hz for hz, until in self._wanted.items() if until >= now]
        if not rates or now - self.last_s < 1.0 / max(rates):
            return
        self.last_s = now
        _ = fused.on_depth
        if self.range_c is None and np.isfinite(fused.temp_thermal_c).any():
            self.range_c = display_range_c(fused.temp_depth_c)
        marked = alarm_rois(alarms.rules, alarms.raised) if alarms else {}
        with self._lock:
            self.frame, self.marked = fused, marked
            self._cache.clear()
            self._videos.clear()

    def wanted(self, hz: float = LIVE_HZ) -> None:
        """Someone looks: keep the pictures coming for WATCH_S, ``hz`` a second (at least
        LIVE_HZ)."""
        with self._lock:
            self._wanted[max(hz, LIVE_HZ)] = time.monotonic() + WATCH_S

    def picture(self, what: str, width: int | None = None) -> Picture | None:
        """The latest ``overlay`` (JPEG) or ``thermal`` (PNG) picture, None before the first
        frame someone looked at."""
        self.wanted()
        with self._lock:
            frame, marked = self.frame, self.marked
            key = (-1 if frame is None else frame.index, what, width)
            cached = self._cache.get(key)
        if frame is None or cached is not None:
            return cached
        range_c = self.range_c or (15.0, 80.0)
        if what == "overlay":
            data = encode(overlay_image(frame, range_c, self.rois, marked), "jpeg", width)
        else:
            data = encode(thermal_image(frame, range_c), "png", width)
        picture = Picture(data, frame.thermal_time_s)
        with self._lock:
            if self.frame is frame:
                self._cache[key] = picture
        return picture

    def video(self, view: str, title: str, hz: float) -> VideoFrame | None:
        """The latest ``overlay`` or ``thermal`` picture (:data:`VIEWS`) framed for a video
        stream that plays at ``hz``: ``title`` and the frame's time above it, the colour scale
        beside it (:func:`video_size`); None before the first frame someone looked at."""
        self.wanted(hz)
        with self._lock:
            frame, marked, cached = self.frame, self.marked, self._videos.get(view)
        if frame is None or cached is not None:
            return cached
        range_c = self.range_c or (15.0, 80.0)
        heading = f"{title}  {time_label(frame.thermal_time_s)}".strip()
        if view == "overlay":
            img = framed(overlay_image(frame, range_c, self.rois, marked), range_c, heading)
        else:
            img = framed(thermal_image(frame, range_c), range_c, heading, reasons=False)
        made = VideoFrame(img, frame.thermal_time_s)
        with self._lock:
            if self.frame is frame:
                self._videos[view] = made
        return made
