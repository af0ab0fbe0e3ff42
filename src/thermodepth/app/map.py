"""``thermodepth map``: a walk-around fused into a 3D model whose surface carries its true
temperature (docs/mapping.md).

Stages: read the source once (every depth frame kept compressed in memory, each pair's
thermal frame and telemetry); the trajectory (a TUM file given, else depth odometry with loop
closure); the geometry (a TSDF of the pairs' depth frames at their poses, meshed); the
temperature (every thermal frame a view at its own pose, fused per vertex with the physics of
:mod:`~thermodepth.mapping.fusion`); the hotspots on the model; the files; and, for a
simulated walk that carries its ground truth, the model measured against it.
"""

from __future__ import annotations

import itertools
import json
import time
import warnings
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numcodecs import Blosc
from numpy.typing import NDArray

from ..calibration import Calibration
from ..camera import RigidTransform, pixel_rays
from ..conditions import Radiometry
from ..csvfile import write_csv
from ..errors import FieldError, InputError
from ..frames import DepthFrame, FramePair, Match
from ..io.model import temperature_colours, write_model_glb, write_model_ply
from ..io.recording import Recording
from ..io.report import Report
from ..mapping.fusion import (
    FUSION_METHODS,
    FusionOptions,
    ThermalView,
    VertexBlocks,
    fuse,
    make_view,
    render_z,
    view_peak,
)
from ..mapping.metrics import measure_map
from ..mapping.model import Hotspot3D, ThermalModel
from ..mapping.odometry import depth_odometry
from ..mapping.render import orbit_views, render
from ..mapping.volume import Volume, lens_for
from ..pipeline import Pipeline, Settings
from ..plotting import pyplot, save_figure
from ..progress import SILENT, Reporter
from ..sources.pairing import DEFAULT_MAX_SKEW_S
from ..trajectory import Trajectory
from .run import Warn, check_source, never_ends, open_choice, spec_of

FloatArray = NDArray[np.float64]
_CODEC = Blosc("lz4", 5, Blosc.BITSHUFFLE)  # depth frames in memory: a few times smaller, fast
_NO_DEPTH = np.zeros((0, 0), np.uint16)  # a kept pair's depth lives in the walk's frames


@dataclass(frozen=True)
class MapOptions:
    """What ``thermodepth map`` reads and how it fuses.

    source: a recording or any source spec; out: the model's folder (created); settings: the
    settings YAML (radiometry, compensation, calibration, hotspot threshold; None: defaults);
    trajectory: a TUM file of the depth camera's poses (None: depth odometry); odometry_fps:
    odometry tracks every n-th depth frame of a faster camera (the poses between
    interpolated; a slower camera's every frame); voxel_m: the voxel size; max_range_m:
    depth beyond it is not fused; fusion: the weights and method
    (:class:`~thermodepth.mapping.fusion.FusionOptions`); every: use every n-th pair as a
    thermal view; hotspot_c: the hotspot threshold (None: the settings'); palette: the
    colours' scale; viewer_save: also write the model for rerun (``.rrd``); the source
    choice as ``run``'s.
    """

    source: str
    out: Path
    settings: Path | None = None
    trajectory: Path | None = None
    odometry_fps: float = 15.0
    voxel_m: float = 0.01
    max_range_m: float = 3.0
    fusion: FusionOptions = field(default_factory=FusionOptions)
    every: int = 1
    hotspot_c: float | None = None
    palette: str = "inferno"
    viewer_save: Path | None = None
    max_skew_s: float = DEFAULT_MAX_SKEW_S
    thermal_latency_s: float = 0.0
    depth_mode: str | None = None
    thermal_camera: str | None = None

    def check(self) -> None:
        """One FieldError for an option that cannot be."""
        check_source(self)
        if never_ends(self.source):
            raise FieldError(
                "source",
                "the simulated rig stands still and never ends: map a walk's recording "
                "(thermodepth simulate walkaround -o walk.zarr)",
            )
        if not 0.002 <= self.voxel_m <= 0.2:
            raise FieldError("voxel_m", f"{self.voxel_m}: give 0.002 .. 0.2 m")
        if not self.max_range_m > 0:
            raise FieldError("max_range_m", "must be > 0")
        if self.every < 1:
            raise FieldError("every", "must be >= 1")
        if not self.odometry_fps > 0:
            raise FieldError("odometry_fps", "must be > 0")
        if self.fusion.method not in FUSION_METHODS:
            raise FieldError(
                "method", f"{self.fusion.method!r}: choose {', '.join(FUSION_METHODS)}"
            )
        if not 0 < self.fusion.max_angle_deg <= 90:
            raise FieldError("max_angle_deg", "give 0 < angle <= 90")
        if self.trajectory is not None and not self.trajectory.is_file():
            raise FieldError("trajectory", f"{self.trajectory}: no such file")


@dataclass
class _Walk:
    """What one read of the source keeps: the depth frames (time, compressed): the pairs'
    and those odometry tracks (``tracked``, their times; None: every one kept), and per pair
    its depth frame's time, its thermal frame, telemetry and radiometry."""

    calibration: Calibration
    trajectory: tuple[Trajectory, str] | None = None  # the source's own (a bag's /tf)
    depth: dict[float, bytes] = field(default_factory=dict)
    tracked: list[float] | None = None
    pairs: list[tuple[FramePair, Radiometry, bool]] = field(default_factory=list)
    shape: tuple[int, int] = (0, 0)

    def keep_depth(self, frame: DepthFrame | FramePair) -> None:
        t = frame.time_s if isinstance(frame, DepthFrame) else frame.depth_time_s
        if t not in self.depth:
            self.depth[t] = _CODEC.encode(np.ascontiguousarray(frame.depth))
            self.shape = frame.depth.shape

    def depth_at(self, time_s: float) -> NDArray[np.uint16]:
        raw = np.frombuffer(_CODEC.decode(self.depth[time_s]), np.uint16)
        return raw.reshape(self.shape)

    def tracked_times(self, fps: float) -> list[float]:
        """The times of the depth frames odometry tracks: ``tracked``, else every n-th kept
        one (:func:`_every_nth`)."""
        if self.tracked is not None:
            return self.tracked
        kept = np.array(sorted(self.depth))
        return [float(t) for t in kept[_every_nth(kept, fps)]]


def _every_nth(times_s: NDArray[np.float64], fps: float) -> NDArray[np.bool_]:
    """Which of the frames at ``times_s`` make a stream of about ``fps``: every n-th, n the
    frames' own rate (median interval) over ``fps``, at least 1; and the last, so that every
    pose is interpolated, none held past the end."""
    keep = np.zeros(len(times_s), bool)
    dt = float(np.nanmedian(np.diff(times_s))) if len(times_s) > 1 else 0.0
    step = max(1, round(1.0 / (dt * fps))) if dt > 0 else 1
    keep[::step] = True
    keep[-1:] = True
    return keep


@dataclass
class MapResult:
    """What a map made: the model, its hotspots, the trajectory used (and whence), the
    report (plain data, as ``map_report.json``), the files written."""

    model: ThermalModel
    hotspots: list[Hotspot3D]
    trajectory: Trajectory
    report: dict[str, Any]
    files: list[Path]


def _read(
    options: MapOptions, settings: Settings, warn: Warn | None, reporter: Reporter
) -> tuple[_Walk, Pipeline]:
    """One pass over the source (module docstring); the pipeline of its calibration."""
    given = Calibration.load(settings.calibration) if settings.calibration else None
    src = open_choice(options, given, warn)
    try:
        cal = src.calibration or given
        if cal is None:
            raise InputError(f"{options.source}: no calibration: give one in the settings")
        walk = _Walk(cal, src.trajectory() if options.trajectory is None else None)
        pipeline = Pipeline(settings, cal, warn=warn)

        def on_event(event: Any) -> None:
            if isinstance(event, DepthFrame):
                walk.keep_depth(event)
            elif isinstance(event, Match):
                walk.keep_depth(event.pair)

        with reporter.task("reading the walk", None) as advance:
            for pair in src.pairs(on_event):
                pipeline.check_sizes(pair)
                radiometry = pipeline.radiometry_of(pair)
                bad = pair.telemetry.in_ffc or pipeline.corrupt(pair, radiometry)
                walk.pairs.append((replace(pair, depth=_NO_DEPTH), radiometry, bad))
                advance(1)
    finally:
        src.close()
    kind, _, path = options.source.partition(":")
    odometry = options.trajectory is None and walk.trajectory is None
    if kind == "recording" and odometry:  # a replay gives its pairs; odometry wants more
        rec = Recording(path, warn=warn or (lambda line: warnings.warn(line, stacklevel=2)))
        rows = np.flatnonzero(_every_nth(rec.depth_times_s(), options.odometry_fps))
        walk.tracked = []
        with reporter.task("reading the depth frames", len(rows)) as advance:
            for frame in rec.depth_frames_at(rows.tolist()):
                walk.keep_depth(frame)
                walk.tracked.append(frame.time_s)
                advance(1)
    if len(walk.pairs) < 2:
        raise InputError(f"{options.source}: {len(walk.pairs)} pairs; a map needs a walk")
    return walk, pipeline


def _trajectory(
    options: MapOptions, walk: _Walk, reporter: Reporter
) -> tuple[Trajectory, dict[str, Any]]:
    """The given TUM file's, else the source's own (a bag's /tf), else depth odometry's over
    every depth frame."""
    if options.trajectory is not None:
        trajectory = Trajectory.load_tum(options.trajectory)
        _check_clock(trajectory, walk, str(options.trajectory))
        return trajectory, {"from": str(options.trajectory), "poses": len(trajectory)}
    if walk.trajectory is not None:
        trajectory, told = walk.trajectory
        _check_clock(trajectory, walk, told)
        return trajectory, {"from": told, "poses": len(trajectory)}
    cal = walk.calibration
    times = walk.tracked_times(options.odometry_fps)
    frames = ((t, walk.depth_at(t)) for t in times)
    with reporter.task("odometry", len(times)) as advance:
        odo = depth_odometry(frames, cal.depth, cal.depth_scale_m, progress=advance)
    return odo.trajectory, {"from": "depth odometry", **odo.summary()}


def _check_clock(trajectory: Trajectory, walk: _Walk, where: str, slack_s: float = 0.5) -> None:
    """InputError when the frames lie outside the poses' times (by more than ``slack_s``): a
    trajectory on another clock would hold its end pose for the whole walk."""
    times = [p.depth_time_s for p, _, _ in walk.pairs] + [
        p.thermal_time_s for p, _, _ in walk.pairs
    ]
    t0, t1 = trajectory.times_s[0], trajectory.times_s[-1]
    if min(times) < t0 - slack_s or max(times) > t1 + slack_s:
        raise InputError(
            f"{where}: poses from {t0:.3f} to {t1:.3f} s but frames from {min(times):.3f} to "
            f"{max(times):.3f} s: give the poses on the frames' clock"
        )


def _depth_m(walk: _Walk, time_s: float, max_range_m: float, every: int = 1) -> NDArray[np.float32]:
    """A kept depth frame in metres (every ``every``-th pixel each way), NaN where none or
    beyond the range."""
    raw = walk.depth_at(time_s)[::every, ::every]
    z = raw.astype(np.float32) * np.float32(walk.calibration.depth_scale_m)
    z[(raw == 0) | (z > max_range_m)] = np.nan
    return z


def _sample_points(
    walk: _Walk, trajectory: Trajectory, options: MapOptions, rays: tuple[FloatArray, FloatArray]
) -> FloatArray:
    """Every 16th pixel each way of the pairs' depth frames, within the range: (N, 3) world
    m, the extent the grid must hold."""
    x, y = rays[0][::16, ::16], rays[1][::16, ::16]
    points = []
    for pair, _, _ in walk.pairs:
        z = _depth_m(walk, pair.depth_time_s, options.max_range_m, every=16)
        ok = np.isfinite(z)
        pts = np.stack([x[ok] * z[ok], y[ok] * z[ok], z[ok]], axis=-1)
        points.append(trajectory.pose_at(pair.depth_time_s).apply(pts))
    world = np.concatenate(points)
    if not len(world):
        raise InputError(f"{options.source}: no depth within {options.max_range_m} m")
    return world


def _geometry(
    walk: _Walk, trajectory: Trajectory, options: MapOptions, reporter: Reporter
) -> Volume:
    """The TSDF of the pairs' depth frames at their poses."""
    cal = walk.calibration
    rays = pixel_rays(cal.depth)
    volume = Volume.of_points(_sample_points(walk, trajectory, options, rays), options.voxel_m)
    # enough depth points to find every block the surfaces cross at the nearest range
    stride = max(1, int(options.voxel_m * 4 * cal.depth.fx / 0.5 / 2))
    with reporter.task("fusing depth", len(walk.pairs)) as advance:
        for pair, _, _ in walk.pairs:
            z = _depth_m(walk, pair.depth_time_s, options.max_range_m)
            volume.integrate(z, cal.depth, trajectory.pose_at(pair.depth_time_s), rays, stride)
            advance(1)
    return volume


def _views(
    walk: _Walk,
    pipeline: Pipeline,
    trajectory: Trajectory,
    vertices: FloatArray,
    blocks: VertexBlocks,
    options: MapOptions,
    reporter: Reporter,
) -> list[ThermalView]:
    """Every ``every``-th pair's thermal frame as a view at its own time's pose: the mesh
    rendered into all of them at once (in parallel, each view only the blocks it may see),
    then each frame's temperatures at the ranges so found."""
    cal = walk.calibration
    rays = pixel_rays(cal.thermal)
    chosen = walk.pairs[:: options.every]
    speeds = trajectory.angular_speed_deg_s([p.thermal_time_s for p, _, _ in chosen])
    rot, pos = trajectory.poses_at([p.thermal_time_s for p, _, _ in chosen])
    poses = [
        cal.thermal_from_depth @ RigidTransform(r, t, "world", "depth").inverse()
        for r, t in zip(rot, pos, strict=True)
    ]
    seen = np.stack([blocks.in_view(p, cal.thermal) for p in poses])
    views = []
    with reporter.task("thermal views", len(chosen)) as advance:
        z_all = render_z(vertices, poses, lens_for(cal.thermal), options.voxel_m, blocks, seen)
        for k, ((pair, radiometry, bad), speed) in enumerate(zip(chosen, speeds, strict=True)):

            def temperature(
                range_m: FloatArray, pair: FramePair = pair, r: Radiometry = radiometry
            ) -> NDArray[np.float32]:
                known = range_m[np.isfinite(range_m)]
                fill = float(np.median(known)) if known.size else 1.0
                rng = np.where(np.isfinite(range_m), range_m, fill)
                temp, _ = pipeline.temperatures(pair.thermal, pair.telemetry.fpa_temp_c, rng, r)
                return temp

            views.append(
                make_view(
                    pair.thermal_time_s, poses[k], z_all[k], seen[k], cal.thermal, rays,
                    options.voxel_m, temperature, bad, float(speed), options.fusion,
                )
            )  # fmt: skip
            advance(1)
    return views


def build_map(
    options: MapOptions, reporter: Reporter = SILENT, warn: Warn | None = None
) -> MapResult:
    """Check the options, read the walk, build the model and write its files into
    ``options.out`` (module docstring)."""
    options = replace(options, source=spec_of(options.source))
    options.check()
    settings = Settings.load(options.settings) if options.settings else Settings()
    out = _output_dir(options.out)
    clock = {"start": time.perf_counter()}
    walk, pipeline = _read(options, settings, warn, reporter)
    clock["read"] = time.perf_counter()
    trajectory, trajectory_info = _trajectory(options, walk, reporter)
    clock["trajectory"] = time.perf_counter()
    volume = _geometry(walk, trajectory, options, reporter)
    vertices, triangles, normals = volume.mesh()
    if not len(vertices):
        raise InputError(f"{options.source}: the depth frames made no surface")
    vertices, triangles, normals, blocks = VertexBlocks.sort(vertices, triangles, normals)
    clock["geometry"] = time.perf_counter()
    views = _views(walk, pipeline, trajectory, vertices, blocks, options, reporter)
    conditions = pipeline.radiometry.conditions
    emissivity = float(conditions.emissivity)
    reflected_c = float(
        conditions.ambient_temp_c
        if conditions.reflected_temp_c is None
        else conditions.reflected_temp_c
    )
    surface = fuse(
        vertices, normals, views, walk.calibration.thermal, options.voxel_m, emissivity,
        reflected_c, options.fusion, blocks,
    )  # fmt: skip
    clock["temperature"] = time.perf_counter()
    model = ThermalModel(vertices, triangles, normals, surface, options.voxel_m)
    threshold = settings.hotspots.threshold_c if options.hotspot_c is None else options.hotspot_c
    hotspots = [
        replace(h, peak_c=peak, peak_views=n)
        for h in model.hotspots(threshold)
        for peak, n in [
            view_peak(
                vertices[h.indices],
                h.normal,
                views,
                walk.calibration.thermal,
                options.voxel_m,
                emissivity,
                reflected_c,
                options.fusion,
            )
        ]
    ]
    hotspots.sort(key=lambda h: -np.nan_to_num(h.peak_c, nan=h.fused_peak_c))
    walk_s = walk.pairs[-1][0].thermal_time_s - walk.pairs[0][0].thermal_time_s
    report = _report(
        options, walk, model, hotspots, trajectory_info, views, threshold, walk_s, clock
    )
    truth = _truth_of(options.source)
    if truth is not None:
        report["against_truth"] = measure_map(
            model, hotspots, trajectory, truth, emissivity, threshold
        )
    files = _write(out, options, model, hotspots, trajectory, report)
    return MapResult(model, hotspots, trajectory, report, files)


def _output_dir(out: Path) -> Path:
    """The model's folder: created, or an empty one (a model is never written over)."""
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise FieldError("out", f"{out}: exists and is not an empty folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise FieldError("out", f"{out}: cannot create ({exc.strerror or exc})") from None
    return out


def _truth_of(spec: str) -> Any:
    """The ground truth a simulated walk's recording carries (None: none)."""
    from ..sim.walk_truth import read_walk_truth

    kind, _, arg = spec.partition(":")
    return read_walk_truth(Path(arg)) if kind == "recording" else None


def temperature_scale(model: ThermalModel, palette: str) -> dict[str, Any]:
    """The one colour scale of every picture and file: the surface's 1st to 99.5th
    percentile, in C."""
    t = model.temp_c[np.isfinite(model.temp_c)]
    lo, hi = np.percentile(t, [1, 99.5]) if t.size else (0.0, 1.0)
    return {
        "palette": palette,
        "min_c": round(float(lo), 2),
        "max_c": round(float(max(hi, lo + 0.1)), 2),
    }


def _report(
    options: MapOptions,
    walk: _Walk,
    model: ThermalModel,
    hotspots: list[Hotspot3D],
    trajectory_info: dict[str, Any],
    views: list[ThermalView],
    threshold_c: float,
    walk_s: float,
    clock: dict[str, float],
) -> dict[str, Any]:
    """``map_report.json``'s content: what went in, what came out, how long each stage took."""
    s = model.surface
    has = np.isfinite(s.temp_c)
    stages = list(clock)
    seconds = {b: round(clock[b] - clock[a], 3) for a, b in itertools.pairwise(stages)}
    total = clock[stages[-1]] - clock[stages[0]]
    return {
        "source": options.source,
        "voxel_m": options.voxel_m,
        "max_range_m": options.max_range_m,
        "fusion": asdict(options.fusion),
        "walk": {
            "duration_s": round(walk_s, 3),
            "depth_frames": len(walk.depth),
            "pairs": len(walk.pairs),
            "views": len(views),
            "views_used": sum(v.weight > 0 for v in views),
            "views_shutter": sum(1 for _, _, bad in walk.pairs[:: options.every] if bad),
            "views_dropped_motion": sum(
                v.weight <= 0 and v.smear_px > options.fusion.smear_px[1] for v in views
            ),
        },
        "trajectory": trajectory_info,
        "mesh": {
            "vertices": len(model.vertices),
            "triangles": len(model.triangles),
            "area_m2": round(model.area_m2(), 4),
            "with_temperature": round(float(has.mean()), 4),
            "views_median": float(np.median(s.views[has])) if has.any() else 0.0,
        },
        "temperature_scale": temperature_scale(model, options.palette),
        "hotspot_threshold_c": threshold_c,
        "hotspots": [h.as_dict() for h in hotspots],
        "seconds": {**seconds, "total": round(total, 3)},
        "speed_vs_real_time": round(walk_s / total, 3) if total > 0 else None,
    }


def _write(
    out: Path,
    options: MapOptions,
    model: ThermalModel,
    hotspots: list[Hotspot3D],
    trajectory: Trajectory,
    report: dict[str, Any],
) -> list[Path]:
    """Every file of the model's folder (docs/mapping.md)."""
    scale = report["temperature_scale"]
    rgb = temperature_colours(model.temp_c, (scale["min_c"], scale["max_c"]), options.palette)
    s = model.surface
    scalars: dict[str, NDArray[Any]] = {
        "temperature": s.temp_c, "weight": s.weight, "views": s.views, "spread": s.spread_c,
        "best": s.best_c, "last_seen": s.last_seen_s,
    }  # fmt: skip
    v, f, n = model.vertices, model.triangles, model.normals
    files = [
        write_model_ply(out / "mesh.ply", v, f, n, rgb, scalars),
        write_model_glb(out / "model.glb", v, f, n, rgb, model.temp_c, scale),
        trajectory.save_tum(out / "trajectory.tum"),
        _write_hotspots(out / "hotspots.csv", hotspots),
    ]
    up = _up(trajectory)
    pictures = _pictures(out, model, rgb, scale, up)
    report["files"] = [p.name for p in files + pictures] + [
        "map_report.json",
        "report.md",
        "report.html",
    ]
    (out / "map_report.json").write_text(json.dumps(report, indent=2) + "\n")
    _write_report(out, report, pictures)
    files += [*pictures, out / "map_report.json", out / "report.md", out / "report.html"]
    if options.viewer_save is not None:
        from ..sinks.viewer import save_model

        files.append(
            save_model(
                options.viewer_save,
                model.vertices,
                model.triangles,
                model.normals,
                rgb,
                trajectory,
                [h.centre_m for h in hotspots],
            )
        )
    return files


def _up(trajectory: Trajectory) -> FloatArray:
    """The world's up as the walk held the camera: the mean of its -y axes (a camera is held
    upright, its y axis pointing down)."""
    up = -trajectory.rotations[:, :, 1].mean(axis=0)
    return up / max(float(np.linalg.norm(up)), 1e-9)


HOTSPOT_FIELDS = (
    "rank",
    "peak_c",
    "peak_views",
    "fused_peak_c",
    "mean_c",
    "centre_x_m",
    "centre_y_m",
    "centre_z_m",
    "peak_x_m",
    "peak_y_m",
    "peak_z_m",
    "area_cm2",
    "extent_m",
    "vertices",
)
"""The columns of the map's ``hotspots.csv``: the report's hotspots, points one axis a column."""


def _write_hotspots(path: Path, hotspots: list[Hotspot3D]) -> Path:
    """One row per hotspot, hottest first: peak and centre (world m), area, extent,
    temperatures, as ``map_report.json`` has them."""
    rows = []
    for rank, h in enumerate(hotspots, 1):
        d = h.as_dict()
        centre, peak = d.pop("centre_m"), d.pop("peak_m")
        d.update({f"centre_{a}_m": v for a, v in zip("xyz", centre, strict=True)})
        d.update({f"peak_{a}_m": v for a, v in zip("xyz", peak, strict=True)})
        rows.append({"rank": rank, **d})
    return write_csv(path, HOTSPOT_FIELDS, rows)


def _pictures(
    out: Path, model: ThermalModel, rgb: NDArray[np.uint8], scale: dict[str, Any], up: FloatArray
) -> list[Path]:
    """Four views of the model (rendered offscreen, from 30 degrees above) with the colour
    scale, framed on what stands out: the surface more than 3 C from the model's median (the
    machine, not the hall round it), else all that has a temperature."""
    plt = pyplot()
    fig, grid = plt.subplots(
        2, 3, figsize=(12.5, 9), gridspec_kw={"width_ratios": [1, 1, 0.04]}, layout="constrained"
    )
    axes = grid[:, :2]
    has = np.isfinite(model.temp_c)
    median_c = float(np.median(model.temp_c[has])) if has.any() else 0.0
    stands_out = has & (np.abs(np.nan_to_num(model.temp_c, nan=median_c) - median_c) > 3.0)
    chosen = next((s for s in (stands_out, has) if s.sum() >= 100), None)
    subject = model.vertices if chosen is None else model.vertices[chosen]
    for ax, (name, view) in zip(axes.ravel(), orbit_views(subject, up, margin=1.3), strict=True):
        ax.imshow(render(model.vertices, model.triangles, model.normals, rgb, view))
        ax.set_title(name)
        ax.axis("off")
    norm = plt.Normalize(scale["min_c"], scale["max_c"])
    sm = plt.cm.ScalarMappable(norm=norm, cmap=scale["palette"])
    grid[1, 2].remove()
    fig.colorbar(sm, cax=grid[0, 2], label="temperature (C)")
    return [save_figure(fig, out / "views.png")]


def _write_report(out: Path, report: dict[str, Any], pictures: list[Path]) -> None:
    """``report.md`` and ``report.html``: the walk, the model, its hotspots, its pictures
    and, for a simulated walk, how it measured against the truth."""
    r = Report("Thermal model")
    w, m = report["walk"], report["mesh"]
    r.text(
        f"{report['source']}: a walk of {w['duration_s']:.1f} s, {w['depth_frames']} depth "
        f"frames, {w['views']} thermal views ({w['views_used']} used; {w['views_shutter']} "
        f"with the shutter closed, {w['views_dropped_motion']} dropped for motion). Trajectory: "
        f"{report['trajectory']['from']}. Voxel {report['voxel_m'] * 100:g} cm, fusion "
        f"{report['fusion']['method']}. Built in {report['seconds']['total']:.1f} s "
        f"({report['speed_vs_real_time']}x real time)."
    )
    r.table(
        ["vertices", "triangles", "area m2", "with a temperature", "views per vertex (median)"],
        [[m["vertices"], m["triangles"], m["area_m2"], m["with_temperature"], m["views_median"]]],
    )
    for p in pictures:
        r.figure(p, "the model, coloured by temperature on one scale")
    r.heading(f"Hotspots (>= {report['hotspot_threshold_c']} C)")
    r.table(
        ["peak C", "mean C", "centre (m)", "area cm2", "extent m"],
        [
            [h["peak_c"], h["mean_c"], h["centre_m"], h["area_cm2"], h["extent_m"]]
            for h in report["hotspots"]
        ],
    )
    truth = report.get("against_truth")
    if truth:
        r.heading("Against the ground truth")
        r.table(["measure", "value"], [[k, v] for k, v in _flat(truth)])
    r.write(out)


def _flat(d: dict[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _flat(v, f"{prefix}{k}.")
        elif not isinstance(v, list):
            yield f"{prefix}{k}", v
