"""The simulated rig: a virtual D435 and a virtual Lepton 3 on one bracket, in a scene.

:class:`Rig` yields :class:`~thermodepth.frames.FramePair` like real cameras and recordings,
and gives exact ground truth (:class:`GroundTruth`) for the same geometry.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration
from ..camera import RigidTransform
from ..frames import FramePair
from .cameras import depth_mode, rig_calibration, thermal_camera
from .d435 import DepthCameraModel, depth_units, ir_image, stereo_shadow
from .lepton import (
    FpaProfile,
    LeptonModel,
    LeptonSensor,
    aperture_radiance,
    constant_fpa,
    footprint_and_blur,
    near_ir_albedo,
    radiance_table,
    surface_properties,
)
from .raycast import Hits, blocked, cast
from .scene import Scene

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
    many, as a session that keeps a pair every few seconds).
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
                ir_hits = cast(self.scene, depth_from_world, cal.depth, ss)
                albedo = footprint_and_blur(near_ir_albedo(self.scene, ir_hits), ss, 0.0)
            return _DepthViews(hits, shadow, albedo)

        views: _DepthViews = self._cached(self._depth_renders, pose, render)
        return views

    def _aperture(self, pose: RigidTransform) -> FloatArray:
        """Noise-free aperture radiance on the thermal grid after footprint and PSF, (h, w),
        at ``pose``."""

        def render() -> FloatArray:
            ss = self.lepton.supersample
            thermal_from_world = self.calibration.thermal_from_depth @ pose.inverse()
            hits = cast(self.scene, thermal_from_world, self.calibration.thermal, ss)
            sub = aperture_radiance(self.scene, hits, radiance_table(self.lepton.response))
            return footprint_and_blur(sub, ss, self.lepton.psf_sigma_px)

        aperture: FloatArray = self._cached(self._thermal_renders, pose, render)
        return aperture

    def pose_at(self, time_s: float) -> RigidTransform:
        """``world_from_depth`` at ``time_s``: the trajectory's, else ``pose``."""
        return self.trajectory(time_s) if self.trajectory is not None else self.pose

    @property
    def aperture(self) -> FloatArray:
        """Noise-free aperture radiance on the thermal grid after footprint and PSF, (h, w),
        at ``pose``."""
        return self._aperture(self.pose)

    def frame(self) -> FramePair:
        """The next frame pair: thermal frame k at start_s + k / fps (k frame_interval_s if
        set), paired with the nearest
        depth frame (30 fps, offset by depth_phase_s); each rendered at its own time's
        pose."""
        k = self._index
        t_thermal = self.start_s + k * (self.frame_interval_s or 1.0 / self.lepton.fps)
        j = round((t_thermal - self.depth_phase_s) * self.depth_model.fps)
        t_depth = j / self.depth_model.fps + self.depth_phase_s
        cal = self.calibration
        seen = self._depth_views(self.pose_at(t_depth))
        depth = depth_units(
            seen.hits.z_m,
            cal.depth.fx,
            cal.depth_scale_m,
            self.depth_model,
            self.rng,
            seen.shadow,
        )
        counts, telemetry = self.sensor.read(t_thermal, self._aperture(self.pose_at(t_thermal)))
        ir = None
        if seen.ir_albedo is not None:
            ir = ir_image(seen.ir_albedo, self.depth_model, self.rng)
        self._index += 1
        return FramePair(
            depth, np.asarray(counts, dtype=np.uint16), t_depth, t_thermal, telemetry, k, ir
        )

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
