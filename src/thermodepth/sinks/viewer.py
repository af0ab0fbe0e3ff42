"""The live 3D view of a run in rerun (rerun-sdk, the ``viewer`` extra).

Entities, in the depth camera's frame (x right, y down, z forward; metres):

- ``world/depth``, ``world/thermal``: both cameras placed from the calibration, with their
  frusta (pinhole models).
- ``images/depth/temperature``: the temperature on the depth grid (RGB on the run's fixed
  colour scale, grey where there is none); ``images/camera/image``: the IR image, else the
  depth; ``images/depth/rois``, ``images/depth/polygons``: the rectangle and polygon ROIs;
  ``images/thermal/counts``: the raw thermal image. (Outside ``world``: an image under a
  camera would also be drawn into the 3D view.)
- ``world/cloud``: the surface points (every depth pixel with a depth, evenly strided down to
  ``viewer.max_points``) coloured by temperature on the same scale, grey where the thermal
  camera does not see them (outside its view, occluded).
- ``world/hotspots``: each hotspot as a box at its centroid, as wide as its area, labelled
  with its maximum, area and whether it is resolvable.
- ``plots/...``: time series of the hottest reading, the VOx temperature and each ROI's mean
  and maximum; ``alarms``: alarm events as a text log; ``legend``: the colour scale.

Every frame is logged on its own time lines (``frame``: the pair index; ``time``: the thermal
frame's time, s). A live run logs at most ``viewer.max_hz`` frames a second (the others are
counted and said at the end), so the viewer never slows the cameras down.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..alarms import RAISED, event_line
from ..errors import FieldError, ThermodepthError
from ..frames import Match, StreamEvent
from ..measure import PolygonRoi, RectRoi
from ..pipeline import FusedFrame, ViewerSettings
from ..plotting import temperature_rgb
from ..trajectory import Trajectory
from .base import BaseSink, RunContext, SessionResult

INSTALL = "the viewer needs rerun-sdk: pip install 'thermodepth[viewer]'"
GREY = np.array([110, 110, 110], np.uint8)
COLORMAP = "inferno"


def colour_scale(temp_c: NDArray[np.floating], range_c: tuple[float, float]) -> NDArray[np.uint8]:
    """RGB (..., 3) uint8 of temperatures (C) on the fixed scale ``range_c`` (inferno,
    clipped at both ends), grey where there is none (NaN)."""
    rgb = temperature_rgb(temp_c, range_c, COLORMAP)
    rgb[~np.isfinite(temp_c)] = GREY
    return rgb


class ViewerSink(BaseSink):
    """Logs a run to rerun (see the module docstring): ``spawn`` a viewer, ``save`` to an
    ``.rrd`` file (``target``: its path) or ``connect`` to a running viewer (``target``: its
    address, ``rerun+http://HOST:9876/proxy``). A live source is logged at most
    ``settings.max_hz`` frames a second; a recording or the simulator frame by frame (they
    have no rate to keep)."""

    def __init__(
        self,
        mode: str,
        target: str | None = None,
        settings: ViewerSettings | None = None,
        warn: Callable[[str], None] | None = None,
    ) -> None:
        if mode not in ("spawn", "save", "connect"):
            raise FieldError("viewer", f"expected spawn, save or connect, got {mode!r}")
        self.mode, self.target = mode, target
        self.settings = settings or ViewerSettings()
        self.max_hz: float | None = self.settings.max_hz
        self.warn = warn or (lambda message: None)
        self.rec: Any = None
        self.logged = 0
        self.skipped = 0
        self._last = float("-inf")
        self._rois: list[Any] = []
        self._counts: dict[int, NDArray[np.uint16]] = {}

    def check(self) -> None:
        try:
            import rerun  # noqa: F401
        except ImportError:
            raise ThermodepthError(INSTALL) from None
        if self.mode == "save":
            path = Path(self.target or "")
            if path.suffix != ".rrd":
                raise FieldError("viewer_save", f"{path}: expected a .rrd file")
            if not path.parent.is_dir():
                raise FieldError("viewer_save", f"{path.parent}: no such folder")
        if self.mode == "spawn" and not (
            os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
        ):
            raise FieldError(
                "viewer",
                "no display to open a viewer on: --viewer-save run.rrd writes a file to open "
                "with `rerun run.rrd` elsewhere, --viewer-connect streams to a running viewer",
            )

    def open(self, context: RunContext) -> None:
        import rerun as rr

        self.check()
        if not context.source.live:
            self.max_hz = None
        rec = rr.RecordingStream(
            "thermodepth", recording_id=f"{context.source.name}-{time.time():.0f}"
        )
        if self.mode == "save":
            rec.save(str(self.target))
        elif self.mode == "connect":
            rec.connect_grpc(self.target or "rerun+http://127.0.0.1:9876/proxy")
        else:
            rec.spawn()
        self.rec = rec
        cal = context.calibration
        if cal is not None:
            self._log_rig(rr, cal)
        if context.pipeline is not None:
            self._rois = context.pipeline.rois
        rec.send_blueprint(_layout())
        lo, hi = self.settings.temp_range_c
        bar = colour_scale(np.linspace(lo, hi, 256)[None, :].repeat(16, axis=0), (lo, hi))
        rec.log("legend/colour_scale", rr.Image(bar), static=True)
        rec.log(
            "legend/text",
            rr.TextDocument(
                f"Temperature colour scale: {lo:g} C (left) to {hi:g} C (right), {COLORMAP}, "
                "the same for every frame; grey: no temperature (outside the thermal view, "
                "occluded, or no depth)."
            ),
            static=True,
        )

    def _log_rig(self, rr: Any, cal: Any) -> None:
        rec = self.rec
        rec.log("world", rr.ViewCoordinates.RDF, static=True)
        for name, intr, pose in (
            ("depth", cal.depth, None),
            ("thermal", cal.thermal, cal.thermal_from_depth.inverse()),
        ):
            if pose is not None:
                rec.log(
                    f"world/{name}",
                    rr.Transform3D(translation=pose.translation_m, mat3x3=pose.rotation),
                    static=True,
                )
            k = [[intr.fx, 0, intr.cx], [0, intr.fy, intr.cy], [0, 0, 1]]
            rec.log(
                f"world/{name}",
                rr.Pinhole(
                    image_from_camera=k,
                    resolution=[intr.width, intr.height],
                    image_plane_distance=0.3,
                ),
                static=True,
            )

    def event(self, event: StreamEvent) -> None:
        if isinstance(event, Match):  # its raw thermal counts, for the frame it becomes
            self._counts[event.pair.index] = event.thermal.counts
            while len(self._counts) > 8:
                self._counts.pop(next(iter(self._counts)))

    def frame(self, fused: FusedFrame) -> None:
        now = time.monotonic()
        if self.max_hz is not None and now - self._last < 1.0 / self.max_hz:
            self.skipped += 1
            return
        self._last = now
        import rerun as rr

        rec, rng = self.rec, self.settings.temp_range_c
        rec.set_time("frame", sequence=fused.index)
        rec.set_time("time", duration=fused.thermal_time_s)
        points, colours = self.cloud(fused)
        rec.log("world/cloud", rr.Points3D(points, colors=colours, radii=0.004))
        rec.log("images/depth/temperature", rr.Image(colour_scale(fused.temp_depth_c, rng)))
        if fused.ir is not None:
            rec.log("images/camera/image", rr.Image(fused.ir))
        else:
            rec.log(
                "images/camera/image",
                rr.DepthImage(fused.depth, meter=1.0 / fused.calibration.depth_scale_m),
            )
        counts = self._counts.pop(fused.index, None)
        if counts is not None:
            rec.log("images/thermal/counts", rr.Image(counts))
        self._log_hotspots(rr, fused)
        self._log_rois(rr, fused)
        hot = fused.hotspots[0].max_c if fused.hotspots else float("nan")
        rec.log("plots/hottest_c", rr.Scalars(hot))
        rec.log("plots/vox_c", rr.Scalars(fused.vox_temp_c))
        for r in fused.rois:
            rec.log(f"plots/roi/{r.name}/mean_c", rr.Scalars(r.mean_c))
            rec.log(f"plots/roi/{r.name}/max_c", rr.Scalars(r.max_c))
        for e in fused.events:
            raised = e["event"] in RAISED
            level = rr.TextLogLevel.WARN if raised else rr.TextLogLevel.INFO
            rec.log("alarms", rr.TextLog(event_line(e), level=level))
        self.logged += 1

    def cloud(self, fused: FusedFrame) -> tuple[NDArray[np.float32], NDArray[np.uint8]]:
        """The surface points (N, 3) m and their colours (N, 3): every depth pixel with a
        depth, evenly strided down to ``max_points``; grey where there is no temperature."""
        valid = np.flatnonzero(fused.depth.ravel() > 0)
        step = max(1, int(np.ceil(valid.size / self.settings.max_points)))
        keep = valid[::step]
        w = fused.depth.shape[1]
        uv = np.stack([keep % w, keep // w], axis=-1)
        z = fused.depth.ravel()[keep] * fused.calibration.depth_scale_m
        points = fused.calibration.depth.deproject(uv, z).astype(np.float32)
        temp = fused.temp_depth_c.ravel()[keep]  # NaN wherever the reason is not OK
        return points, colour_scale(temp, self.settings.temp_range_c)

    def _log_hotspots(self, rr: Any, fused: FusedFrame) -> None:
        if not fused.hotspots:
            self.rec.log("world/hotspots", rr.Clear(recursive=False))
            return
        centres = [h.centroid_m for h in fused.hotspots]
        sides = [max(float(np.sqrt(h.area_m2)), 0.01) if np.isfinite(h.area_m2) else 0.02
                 for h in fused.hotspots]  # fmt: skip
        labels = [
            f"{h.max_c:.1f} C, {h.area_m2 * 1e4:.0f} cm2"
            + ("" if h.resolvable else ", too small to read fully")
            for h in fused.hotspots
        ]
        self.rec.log(
            "world/hotspots",
            rr.Boxes3D(
                centers=centres,
                half_sizes=[[s / 2, s / 2, 0.005] for s in sides],
                labels=labels,
                colors=[[0, 255, 255]] * len(centres),
            ),
        )

    def _log_rois(self, rr: Any, fused: FusedFrame) -> None:
        stats = {r.name: r for r in fused.rois}
        boxes, labels, strips, strip_labels = [], [], [], []
        for roi in self._rois:
            s = stats.get(roi.name)
            text = (
                roi.name
                if s is None or not s.n
                else f"{roi.name}: {s.mean_c:.1f} / {s.max_c:.1f} C"
            )
            if isinstance(roi, RectRoi):
                boxes.append([roi.u0, roi.v0, roi.u1 - roi.u0, roi.v1 - roi.v0])
                labels.append(text)
            elif isinstance(roi, PolygonRoi):
                strips.append([*roi.vertices, roi.vertices[0]])
                strip_labels.append(text)
        if boxes:
            b = np.asarray(boxes, np.float32)
            self.rec.log(
                "images/depth/rois", rr.Boxes2D(mins=b[:, :2], sizes=b[:, 2:], labels=labels)
            )
        if strips:
            self.rec.log("images/depth/polygons", rr.LineStrips2D(strips, labels=strip_labels))

    def close(self, result: SessionResult) -> None:
        if self.rec is None:
            return
        try:
            self.rec.flush(timeout_sec=10.0)
        except RuntimeError as exc:  # a viewer that went away: the run is done anyway
            self.warn(f"viewer: {str(exc).splitlines()[0]}")
        self.rec.disconnect()

    def summary(self) -> str:
        where = {"save": f"saved to {self.target}", "connect": f"sent to {self.target}"}
        rate = (
            f" ({self.skipped} skipped to keep to {self.max_hz:g} frames/s)" if self.skipped else ""
        )
        return f"viewer: {self.logged} frames logged{rate}, {where.get(self.mode, 'spawned')}"


def _layout() -> Any:
    """The viewer's layout: the 3D scene large, beside it the temperature and raw thermal
    images, the time series, the alarms and the colour scale."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(
                origin="world",
                name="3D: temperature on the surfaces",
                # behind and above the rig, looking 1.5 m ahead (x right, y down, z forward)
                eye_controls=rrb.EyeControls3D(
                    position=[0.6, -0.7, -0.9], look_target=[0.0, 0.0, 1.5], eye_up=[0, -1, 0]
                ),
            ),
            rrb.Vertical(
                rrb.Spatial2DView(origin="images/depth", name="on the depth image"),
                rrb.Horizontal(
                    rrb.Spatial2DView(origin="images/thermal", name="raw thermal counts"),
                    rrb.Spatial2DView(origin="images/camera", name="IR or depth image"),
                ),
                rrb.TimeSeriesView(origin="plots", name="hottest, VOx, ROIs (C)"),
                rrb.TextLogView(origin="alarms", name="alarms"),
                rrb.Spatial2DView(origin="legend/colour_scale", name="colour scale"),
                rrb.TextDocumentView(origin="legend/text", name="legend"),
                row_shares=[3, 2, 2, 1, 1, 1],
            ),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline="frame", play_state="following"),  # the latest frame
        collapse_panels=True,
    )


def check_viewer_options(spawn: bool, save: Path | None, connect: str | None) -> None:
    """At most one way to view; FieldError otherwise."""
    if sum((spawn, save is not None, connect is not None)) > 1:
        raise FieldError("viewer", "one of --viewer, --viewer-save, --viewer-connect")


def viewer_sink(
    spawn: bool,
    save: Path | None,
    connect: str | None,
    settings: ViewerSettings,
    warn: Callable[[str], None] | None = None,
) -> ViewerSink | None:
    """The viewer sink the options ask for (None: none)."""
    check_viewer_options(spawn, save, connect)
    if save is not None:
        return ViewerSink("save", str(save), settings, warn)
    if connect is not None:
        return ViewerSink("connect", connect, settings, warn)
    return ViewerSink("spawn", None, settings, warn) if spawn else None


def save_model(
    path: Path,
    vertices: NDArray[np.float64],
    triangles: NDArray[np.int64],
    normals: NDArray[np.float64],
    rgb: NDArray[np.uint8],
    trajectory: Trajectory,
    hotspots_m: list[NDArray[np.float64]],
) -> Path:
    """A thermal model for rerun (``rerun model.rrd``): the mesh coloured by temperature, the
    camera's path, the hotspots' centres (world m)."""
    import rerun as rr

    rec = rr.RecordingStream("thermodepth-map")
    rec.save(str(path))
    rec.log("world", rr.ViewCoordinates.RDF, static=True)
    rec.log(
        "world/model",
        rr.Mesh3D(
            vertex_positions=vertices,
            triangle_indices=triangles,
            vertex_normals=normals,
            vertex_colors=rgb,
        ),
        static=True,
    )
    rec.log("world/trajectory", rr.LineStrips3D([trajectory.translations_m]), static=True)
    if hotspots_m:
        rec.log("world/hotspots", rr.Points3D(np.array(hotspots_m), radii=0.02), static=True)
    rec.flush()
    return path
