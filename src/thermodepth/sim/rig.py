"""The simulated rig: a virtual D435 and a virtual Lepton 3 on one bracket, in a scene.

:class:`Rig` yields :class:`~thermodepth.frames.FramePair` like real cameras and recordings,
and gives exact ground truth (:class:`GroundTruth`) for the same geometry.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration
from ..camera import Intrinsics, RigidTransform, rotation_from_euler
from ..frames import FramePair
from .d435 import DepthCameraModel, depth_units, ir_image, stereo_shadow
from .lepton import (
    FpaProfile,
    LeptonModel,
    LeptonSensor,
    aperture_radiance,
    constant_fpa,
    footprint_and_blur,
    radiance_table,
    surface_properties,
)
from .raycast import Hits, blocked, cast
from .scene import Scene

FloatArray = NDArray[np.float64]


def default_calibration() -> Calibration:
    """The virtual rig's true calibration.

    Depth: 1280x720, fx = fy = 645, principal point at the centre, no distortion, 1 mm units.
    Thermal: 160x120, HFOV 56 deg (fx = 80 / tan 28 deg = 150.5), principal point ~1 px off
    centre, mild barrel distortion. The Lepton sits 40 mm left of, 6 mm below and 3 mm
    behind the depth origin (the D435's right imager is on the other side, so the band the
    Lepton cannot see behind near objects keeps valid depth), turned by about a degree:
    parallax at 0.5 m is ~12 thermal px.
    """
    depth = Intrinsics(1280, 720, 645.0, 645.0, 639.5, 359.5)
    fx_t = 80.0 / np.tan(np.radians(28.0))
    thermal = Intrinsics(
        160, 120, fx_t, fx_t * 1.002, 80.6, 58.8, np.array([-0.08, 0.02, 0.0004, -0.0003, 0.0])
    )
    rot = rotation_from_euler(np.radians(0.4), np.radians(-0.6), np.radians(1.1))
    centre_in_depth = np.array([-0.040, 0.006, -0.003])
    t = RigidTransform(rot, -rot @ centre_in_depth, "thermal", "depth")
    return Calibration(depth, thermal, 0.001, t)


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


@dataclass(eq=False)
class Rig:
    """A depth camera and a thermal camera looking at ``scene`` from ``pose``.

    pose: ``world_from_depth``; calibration: the rig's true calibration; fpa: FPA temperature
    profile; seed: all randomness (noise, fixed pattern) follows from it; with_ir: also render
    the depth camera's infrared image; start_s: time of the first thermal frame.
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

    def __post_init__(self) -> None:
        if (self.pose.to_frame, self.pose.from_frame) != ("world", "depth"):
            raise ValueError(f"pose must be world_from_depth, got {self.pose.name}")
        self.rng = np.random.default_rng(self.seed)
        self.sensor = LeptonSensor(self.lepton, self.calibration.thermal.shape, self.fpa, self.rng)
        self._index = 0

    # -- frames ----------------------------------------------------------------------------

    @property
    def depth_from_world(self) -> RigidTransform:
        return self.pose.inverse()

    @property
    def thermal_from_world(self) -> RigidTransform:
        return self.calibration.thermal_from_depth @ self.depth_from_world

    @cached_property
    def _depth_hits(self) -> Hits:
        return cast(self.scene, self.depth_from_world, self.calibration.depth)

    @cached_property
    def _shadow(self) -> NDArray[np.bool_]:
        return stereo_shadow(
            self._depth_hits.z_m, self.calibration.depth.fx, self.depth_model.baseline_m
        )

    @cached_property
    def aperture(self) -> FloatArray:
        """Noise-free aperture radiance on the thermal grid after footprint and PSF, (h, w)."""
        ss = self.lepton.supersample
        hits = cast(self.scene, self.thermal_from_world, self.calibration.thermal, ss)
        sub = aperture_radiance(self.scene, hits, radiance_table(self.lepton.response))
        return footprint_and_blur(sub, ss, self.lepton.psf_sigma_px)

    @cached_property
    def _ir_albedo(self) -> FloatArray:
        """Near-IR albedo per depth pixel (H, W): the mean over its sub-rays (per pose)."""
        ss = self.depth_model.ir_supersample
        hits = cast(self.scene, self.depth_from_world, self.calibration.depth, ss)
        return footprint_and_blur(surface_properties(self.scene, hits)[2], ss, 0.0)

    def frame(self) -> FramePair:
        """The next frame pair: thermal frame k at start_s + k / fps, paired with the nearest
        depth frame (30 fps, offset by depth_phase_s)."""
        k = self._index
        t_thermal = self.start_s + k / self.lepton.fps
        j = round((t_thermal - self.depth_phase_s) * self.depth_model.fps)
        t_depth = j / self.depth_model.fps + self.depth_phase_s
        cal = self.calibration
        depth = depth_units(
            self._depth_hits.z_m,
            cal.depth.fx,
            cal.depth_scale_m,
            self.depth_model,
            self.rng,
            self._shadow,
        )
        counts, telemetry = self.sensor.read(t_thermal, self.aperture)
        ir = ir_image(self._ir_albedo, self.depth_model, self.rng) if self.with_ir else None
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
        dh = self._depth_hits
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
