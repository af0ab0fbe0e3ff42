"""The simulated rig: a virtual D435 and a virtual Lepton 3 on one bracket, in a scene.

:class:`Rig` yields :class:`~thermodepth.frames.FramePair` like real cameras and recordings
(or every frame of both cameras on their own clocks, :meth:`Rig.stream`), and gives exact
ground truth (:class:`GroundTruth`) for the same geometry.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration
from ..camera import RigidTransform
from ..frames import DepthFrame, FramePair, Match, StreamEvent, ThermalFrame, pair_of
from .cameras import depth_mode, rig_calibration, thermal_camera
from .d435 import DepthCameraModel, depth_units, ir_image, stereo_shadow
from .lepton import (
    FpaProfile,
    LeptonModel,
    LeptonSensor,
    bolometer_memory,
    constant_fpa,
    radiance_table,
)
from .raycast import Hits, blocked, cast
from .scene import Scene
from .shading import render_aperture, render_ir_albedo, surface_properties

FloatArray = NDArray[np.float64]


def default_calibration() -> Calibration:
    """The virtual rig's true calibration with its default cameras (a Lepton 3 beside a D435
    at 1280x720; :func:`~.cameras.rig_calibration`).

    Depth: 1280x720, fx = fy = 645, principal point at the centre, no distortion, 1 mm units.
    Thermal: 160x120, HFOV 56 deg (fx = 80 / tan 28 deg = 150.5), principal point ~1 px off
    centre, mild barrel distortion. The Lepton sits 40 mm left of, 6 mm below and 3 mm
    behind the depth origin, turned by about a degree: parallax at 0.5 m is ~12 thermal px.
    """
    return rig_calibration()


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """Exact geometry and temperatures for one rig pose (noise-free).

    Depth grid (H, W): depth_z_m (inf where nothing), depth_range_m, depth_temp_k,
    depth_rect (-1 = nothing); the true thermal pixel (u, v) of every depth pixel's surface
    point, thermal_pixel_of_depth (H, W, 2), NaN where nothing is hit or it falls outside the
    thermal image; visible_in_thermal (inside the thermal image and not hidden) and
    occluded_in_thermal (inside, but a nearer surface hides it from the thermal camera).
    Thermal grid (h, w), rays through pixel centres: thermal_z_m, thermal_range_m,
    thermal_temp_k, thermal_rect.
    """

    calibration: Calibration
    depth_z_m: FloatArray
    depth_range_m: FloatArray
    depth_temp_k: FloatArray
    depth_rect: NDArray[np.int64]
    thermal_pixel_of_depth: FloatArray
    visible_in_thermal: NDArray[np.bool_]
    occluded_in_thermal: NDArray[np.bool_]
    thermal_z_m: FloatArray
    thermal_range_m: FloatArray
    thermal_temp_k: FloatArray
    thermal_rect: NDArray[np.int64]


Trajectory = Callable[[float], RigidTransform]
"""``world_from_depth`` of a moving rig as a function of time in seconds."""


@dataclass(frozen=True, eq=False)
class _DepthViews:
    """What the depth camera sees from one rig pose, noise-free: its hits, the stereo
    shadow, and the near-IR albedo per pixel (H, W) when asked for."""

    hits: Hits
    shadow: NDArray[np.bool_]
    ir_albedo: FloatArray | None


_RENDERS_KEPT = 4  # per camera: a held pose renders once, a moving one each frame


@dataclass(eq=False)
class Rig:
    """A depth camera and a thermal camera looking at ``scene`` from ``pose``.

    pose: ``world_from_depth``; trajectory: a moving rig's ``world_from_depth`` over time
    (None: it stays at ``pose``); each camera is rendered at the pose of its own exposure
    time, as real cameras that do not expose at the same instant see a moving scene;
    calibration: the rig's true calibration; fpa: FPA temperature profile; seed: all
    randomness (noise, fixed pattern) follows from it; with_ir: also render the depth
    camera's infrared image; start_s: time of the first thermal frame; frame_interval_s: time
    between the thermal frames it gives (None: every frame, 1 / fps; longer: one frame in so
    many, as a session that keeps a pair every few seconds); thermal_time_constant_s: the
    microbolometer's thermal time constant (None: it follows the scene at once): a moving
    rig's thermal image is then the exponentially weighted mean of the scene over the time
    constants before the frame (:func:`~.lepton.bolometer_memory`), smeared along the motion.
    Noise-free renders are cached per pose; frames differ by noise and the sensor's state.
    """

    scene: Scene
    pose: RigidTransform
    calibration: Calibration = field(default_factory=default_calibration)
    depth_model: DepthCameraModel = field(default_factory=DepthCameraModel)
    lepton: LeptonModel = field(default_factory=LeptonModel)
    fpa: FpaProfile = field(default_factory=lambda: constant_fpa(308.15))
    seed: int = 0
    with_ir: bool = False
    start_s: float = 0.0
    depth_phase_s: float = 0.004
    trajectory: Trajectory | None = None
    frame_interval_s: float | None = None
    thermal_time_constant_s: float | None = None

    @classmethod
    def of_cameras(
        cls,
        scene: Scene,
        pose: RigidTransform,
        thermal: str | None = None,
        depth: str | None = None,
        **kwargs: Any,
    ) -> Rig:
        """A rig of the simulated cameras named (:data:`~.cameras.THERMAL_CAMERAS`, a depth
        mode ``WxH[@FPS]`` of :data:`~.cameras.DEPTH_MODES`; None: the Lepton 3 and
        1280x720 at 30 fps) with its true calibration; ``kwargs`` as the constructor's (a
        ``lepton`` given replaces the camera's sensor)."""
        cam, mode = thermal_camera(thermal), depth_mode(depth)
        kwargs.setdefault("lepton", cam.sensor)
        kwargs.setdefault("depth_model", DepthCameraModel(fps=mode.fps))
        return cls(scene, pose, rig_calibration(cam, mode), **kwargs)

    def __post_init__(self) -> None:
        if (self.pose.to_frame, self.pose.from_frame) != ("world", "depth"):
            raise ValueError(f"pose must be world_from_depth, got {self.pose.name}")
        self.rng = np.random.default_rng(self.seed)
        self.sensor = LeptonSensor(self.lepton, self.calibration.thermal.shape, self.fpa, self.rng)
        self._index = 0
        self._depth_renders: OrderedDict[bytes, _DepthViews] = OrderedDict()
        self._thermal_renders: OrderedDict[bytes, FloatArray] = OrderedDict()

    # -- frames ----------------------------------------------------------------------------

    @property
    def depth_from_world(self) -> RigidTransform:
        return self.pose.inverse()

    @property
    def thermal_from_world(self) -> RigidTransform:
        return self.calibration.thermal_from_depth @ self.depth_from_world

    def _cached(
        self, cache: OrderedDict[bytes, Any], pose: RigidTransform, make: Callable[[], Any]
    ) -> Any:
        """``make()`` for ``pose``, kept in ``cache`` (the last few poses)."""
        key = pose.rotation.tobytes() + pose.translation_m.tobytes() + bytes([self.with_ir])
        if key not in cache:
            cache[key] = make()
            while len(cache) > _RENDERS_KEPT:
                cache.popitem(last=False)
        cache.move_to_end(key)
        return cache[key]

    def _depth_views(self, pose: RigidTransform) -> _DepthViews:
        """The depth camera's noise-free renders at ``pose`` (``world_from_depth``)."""

        def render() -> _DepthViews:
            cal = self.calibration
            depth_from_world = pose.inverse()
            hits = cast(self.scene, depth_from_world, cal.depth)
            shadow = stereo_shadow(hits.z_m, cal.depth.fx, self.depth_model.baseline_m)
            albedo = None
            if self.with_ir:  # near-IR albedo: the mean over each pixel's sub-rays
                ss = self.depth_model.ir_supersample
                albedo = render_ir_albedo(self.scene, depth_from_world, cal.depth, ss)
            return _DepthViews(hits, shadow, albedo)

        views: _DepthViews = self._cached(self._depth_renders, pose, render)
        return views

    def _aperture(self, pose: RigidTransform) -> FloatArray:
        """Noise-free aperture radiance on the thermal grid after footprint and PSF, (h, w),
        at ``pose``."""

        def render() -> FloatArray:
            return render_aperture(
                self.scene,
                self.calibration.thermal_from_depth @ pose.inverse(),
                self.calibration.thermal,
                self.lepton.supersample,
                self.lepton.psf_sigma_px,
                radiance_table(self.lepton.response),
            )

        aperture: FloatArray = self._cached(self._thermal_renders, pose, render)
        return aperture

    def aperture_at(self, time_s: float) -> FloatArray:
        """Noise-free aperture radiance the thermal sensor sees at ``time_s``, (h, w): the
        render at that time's pose; with a thermal time constant and a rig that moved, the
        weighted mean of renders at the poses of :func:`~.lepton.bolometer_memory`'s lags
        before it (the image smears along the motion)."""
        pose = self.pose_at(time_s)
        tau = self.thermal_time_constant_s
        if tau is None or self.trajectory is None:
            return self._aperture(pose)
        lags_s, weights = bolometer_memory(tau)
        poses = [self.pose_at(time_s - lag) for lag in lags_s]
        if all(_same_pose(p, pose) for p in poses):  # held: one render, as without memory
            return self._aperture(pose)
        renders = np.stack([self._aperture(p) for p in poses])
        return np.asarray(np.einsum("k,khw->hw", weights, renders))

    def pose_at(self, time_s: float) -> RigidTransform:
        """``world_from_depth`` at ``time_s``: the trajectory's, else ``pose``."""
        return self.trajectory(time_s) if self.trajectory is not None else self.pose

    @property
    def aperture(self) -> FloatArray:
        """Noise-free aperture radiance on the thermal grid after footprint and PSF, (h, w),
        at ``pose``."""
        return self._aperture(self.pose)

    def thermal_time_s(self, index: int) -> float:
        """Time of thermal frame ``index``: start_s + index / fps (index frame_interval_s if
        set)."""
        return self.start_s + index * (self.frame_interval_s or 1.0 / self.lepton.fps)

    def depth_time_s(self, index: int) -> float:
        """Time of depth frame ``index`` on the depth camera's own clock: index / fps (30 fps)
        + depth_phase_s."""
        return index / self.depth_model.fps + self.depth_phase_s

    def depth_index_near(self, time_s: float) -> int:
        """The depth frame nearest ``time_s``."""
        return round((time_s - self.depth_phase_s) * self.depth_model.fps)

    def _depth(self, index: int) -> tuple[NDArray[np.uint16], _DepthViews]:
        """Depth frame ``index`` (noisy Z16) and the renders it was made of."""
        cal = self.calibration
        seen = self._depth_views(self.pose_at(self.depth_time_s(index)))
        depth = depth_units(
            seen.hits.z_m, cal.depth.fx, cal.depth_scale_m, self.depth_model, self.rng, seen.shadow
        )
        return depth, seen

    def _ir(self, seen: _DepthViews) -> NDArray[np.uint8] | None:
        """The IR image of a depth frame's renders (None without ``with_ir``)."""
        if seen.ir_albedo is None:
            return None
        return ir_image(seen.ir_albedo, self.depth_model, self.rng)

    def _thermal(self) -> ThermalFrame:
        """The next thermal frame (the sensor reads frames in order)."""
        k = self._index
        t = self.thermal_time_s(k)
        counts, telemetry = self.sensor.read(t, self.aperture_at(t))
        self._index += 1
        return ThermalFrame(np.asarray(counts, dtype=np.uint16), t, k, telemetry)

    def frame(self) -> FramePair:
        """The next frame pair: thermal frame k at :meth:`thermal_time_s`, paired with the
        nearest depth frame (30 fps, offset by depth_phase_s); each rendered at its own
        time's pose."""
        j = self.depth_index_near(self.thermal_time_s(self._index))
        depth, seen = self._depth(j)
        thermal = self._thermal()
        ir = self._ir(seen)  # drawn after the thermal noise, as it always was
        return FramePair(
            depth,
            thermal.counts,
            self.depth_time_s(j),
            thermal.time_s,
            thermal.telemetry,
            thermal.index,
            ir,
        )

    def depth_frame(self, index: int) -> DepthFrame:
        """Depth frame ``index`` of the depth camera's own clock (:meth:`depth_time_s`)."""
        depth, seen = self._depth(index)
        return DepthFrame(depth, self.depth_time_s(index), index, self._ir(seen))

    def _plan(self, duration_s: float) -> tuple[range, dict[int, int]]:
        """The depth frames (indices) and the thermal frames (each index with its depth
        frame's) of :meth:`stream` over ``duration_s``."""
        end_s = self.start_s + duration_s + 1e-9
        near: dict[int, int] = {}
        k = self._index
        while self.thermal_time_s(k) <= end_s:
            near[k] = self.depth_index_near(self.thermal_time_s(k))
            k += 1
        fps, phase = self.depth_model.fps, self.depth_phase_s
        first = min([math.ceil((self.start_s - phase) * fps - 1e-9), *near.values()])
        last = max([math.floor((end_s - phase) * fps), *near.values()])
        return range(first, last + 1), near

    def stream_counts(self, duration_s: float) -> tuple[int, int]:
        """How many depth and thermal frames :meth:`stream` gives over ``duration_s``."""
        depth, near = self._plan(duration_s)
        return len(depth), len(near)

    def stream(self, duration_s: float) -> Iterator[StreamEvent]:
        """Every frame of both cameras from start_s for ``duration_s`` (a new rig's; after
        :meth:`frame` calls, from the next thermal frame), as a live rig sends them: the
        depth frames on the depth camera's clock (:meth:`depth_time_s`) and the thermal
        frames on the thermal camera's (:meth:`thermal_time_s`), in time order, each thermal
        frame's :class:`~thermodepth.frames.Match` with the nearest depth frame as soon as
        both are out (numbered as the thermal frame). Each frame is rendered once, at its
        own time's pose."""
        depth_indices, near = self._plan(duration_s)
        j, last_j = depth_indices.start, depth_indices.stop - 1
        last_k = max(near, default=self._index - 1)
        depth: dict[int, DepthFrame] = {}
        pending: list[ThermalFrame] = []  # thermal frames whose depth frame is to come
        while j <= last_j or self._index <= last_k:
            k = self._index
            if k > last_k or (j <= last_j and self.depth_time_s(j) <= self.thermal_time_s(k)):
                depth[j] = self.depth_frame(j)
                yield depth[j]
                j += 1
            else:
                pending.append(self._thermal())
                yield pending[-1]
            while pending and near[pending[0].index] < j:
                thermal = pending.pop(0)
                d = depth[near[thermal.index]]
                yield Match(d, thermal, pair_of(d, thermal, thermal.index))
            keep = near[pending[0].index] if pending else near.get(self._index, j)
            for old in [i for i in depth if i < keep]:
                del depth[old]

    def frames(self, n: int | None = None) -> Iterator[FramePair]:
        """Yield ``n`` frame pairs (forever if None)."""
        i = 0
        while n is None or i < n:
            yield self.frame()
            i += 1

    # -- ground truth ----------------------------------------------------------------------

    def truth(self) -> GroundTruth:
        """Exact, noise-free geometry and temperatures for the current pose."""
        cal = self.calibration
        dh = self._depth_views(self.pose).hits
        hit = dh.rect >= 0
        u, v = cal.depth.pixel_grid()
        pts_d = cal.depth.deproject(np.stack([u, v], axis=-1), np.where(hit, dh.z_m, np.nan))
        pts_t = cal.thermal_from_depth.apply(pts_d)
        px_t = cal.thermal.project(pts_t)
        inside = hit & cal.thermal.contains(px_t)
        px_t[~inside] = np.nan
        hidden = blocked(
            self.scene, self.thermal_from_world, np.where(inside[..., None], pts_t, np.nan)
        )
        th = cast(self.scene, self.thermal_from_world, cal.thermal)
        return GroundTruth(
            calibration=cal,
            depth_z_m=dh.z_m,
            depth_range_m=dh.range_m,
            depth_temp_k=surface_properties(self.scene, dh)[0],
            depth_rect=dh.rect,
            thermal_pixel_of_depth=px_t,
            visible_in_thermal=inside & ~hidden,
            occluded_in_thermal=inside & hidden,
            thermal_z_m=th.z_m,
            thermal_range_m=th.range_m,
            thermal_temp_k=surface_properties(self.scene, th)[0],
            thermal_rect=th.rect,
        )


def _same_pose(a: RigidTransform, b: RigidTransform) -> bool:
    return bool(
        np.array_equal(a.rotation, b.rotation) and np.array_equal(a.translation_m, b.translation_m)
    )
