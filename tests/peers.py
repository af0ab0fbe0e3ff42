"""Peers of :mod:`thermodepth.registration` for its tests and the registration benchmark
(``bench/bench_registration.py`` imports them from here).

Plain functions (and one small class); none of them times itself, the caller does.

- :class:`RsAlign`: librealsense's ``rs.align`` on a camera-less ``software_device``, both
  directions (needs ``pyrealsense2`` and the system library libusb-1.0).
- :func:`register_depth_cv2`: OpenCV's ``registerDepth`` (depth -> thermal only).
- :func:`numpy_reference`, :func:`reference_depth_to_thermal`,
  :func:`reference_thermal_to_depth`: our own algorithm written plainly in float64 numpy, the
  reference the tests hold the numba kernels to.

What the peers compute, measured on the simulated rig (tests/test_peers.py holds them to it):

``rs.align`` maps pixel *corners*, not centres, and rounds with a C cast (truncation):

- depth -> other: each depth pixel lands where its top-left corner (u - 0.5, v - 0.5)
  projects; a target pixel keeps the *smallest depth value* of those that land in it. The
  value is the raw depth (Z in the depth camera's frame, depth units), not Z in the target's
  frame (our ``DepthOnThermal.z_m``): they differ by the rig's baseline and rotation.
  (librealsense only takes both corners and fills the rectangle between them when the target
  has more pixels per degree than the depth camera; a Lepton has fewer.)
- other -> depth: each depth pixel takes the target pixel of its bottom-right corner
  (u + 0.5, v + 0.5); no occlusion test, so hot foreground bleeds onto what it hides.
- The pixel index is ``int(x + 0.5)``, a truncation towards zero: column and row 0 also take
  what lands in (-1.5, -0.5], one pixel beyond the image edge.
- ``modified_brown_conrady`` applies the tangential terms to the *radially distorted*
  coordinates (OpenCV applies them to the undistorted ones); ``rs.align`` ignores every
  other distortion model. With our k1..k3 and small p1, p2 the difference is ~1e-3 px.
- ``rs2_extrinsics.rotation`` is column-major: pass R transposed, row by row.

``cv2.registerDepth`` (OpenCV 5: module 3d, in ``opencv-python-headless`` itself; OpenCV 4:
``cv2.rgbd.registerDepth`` from opencv-contrib) projects every depth pixel centre, rounds to
the nearest pixel and keeps the minimum Z in the *target* frame: the same quantity as ours.
It ignores depth-camera distortion, takes the transform as a 4x4 matrix and crashes when the
output plane is smaller than the depth image (opencv_contrib issue 3761; OpenCV 5.0 too).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from thermodepth.calibration import Calibration
from thermodepth.registration import OcclusionTolerance, Reason

if TYPE_CHECKING:
    from thermodepth.camera import Intrinsics

F64 = NDArray[np.float64]

# ---------------------------------------------------------------------------------------------
# librealsense rs.align
# ---------------------------------------------------------------------------------------------


def import_pyrealsense2() -> Any:
    """The pyrealsense2 module, or ImportError saying what is missing."""
    try:
        import pyrealsense2 as rs
    except ImportError as exc:  # missing package, or libusb-1.0 missing on the system
        raise ImportError(
            "RsAlign needs pyrealsense2 (pip install 'thermodepth[realsense]', x86_64 only) "
            f"and the system library libusb-1.0-0 (apt-get install libusb-1.0-0): {exc}"
        ) from exc
    return rs


class RsAlign:
    """librealsense's ``rs.align`` between our depth and thermal grids, without a camera.

    Set-up (once): a ``pyrealsense2.software_device`` with a depth sensor (Z16 at the depth
    intrinsics, depth units = ``calibration.depth_scale_m``, 30 fps) and a sensor standing in
    for the thermal camera (librealsense has no thermal stream type: infrared index 1, Y16,
    the thermal intrinsics, distortion ``modified_brown_conrady`` with our [k1, k2, p1, p2,
    k3], or none when all are zero), the depth -> thermal extrinsics, a syncer and one
    ``rs.align`` per direction. Each call then does only the per-frame work: feed a frame
    pair, wait for the synced frameset, ``align.process`` it, copy the result out.

    The depth camera must have no distortion: librealsense would need it in its own inverse
    model, which our OpenCV coefficients are not. Call :meth:`close` (or use ``with``) when
    done. Raises ImportError when pyrealsense2 or libusb cannot be loaded.
    """

    FPS = 30
    TIMEOUT_MS = 2000

    def __init__(self, calibration: Calibration) -> None:
        rs = import_pyrealsense2()
        if calibration.depth.has_distortion:
            raise ValueError(
                "RsAlign: the depth camera has distortion coefficients; rs.align only undoes "
                "an inverse_brown_conrady model, which OpenCV coefficients are not"
            )
        self._rs = rs
        self.calibration = calibration
        d, t = calibration.depth, calibration.thermal
        self._device = rs.software_device()
        self._depth_sensor = self._device.add_sensor("Depth")
        self._depth_sensor.add_read_only_option(rs.option.depth_units, calibration.depth_scale_m)
        self._thermal_sensor = self._device.add_sensor("Thermal (as infrared)")
        model = rs.distortion.modified_brown_conrady if t.has_distortion else rs.distortion.none
        self._depth_profile = self._depth_sensor.add_video_stream(
            self._stream(rs.stream.depth, 0, rs.format.z16, d, rs.distortion.none)
        ).as_video_stream_profile()
        self._thermal_profile = self._thermal_sensor.add_video_stream(
            self._stream(rs.stream.infrared, 1, rs.format.y16, t, model)
        ).as_video_stream_profile()
        self._depth_profile.register_extrinsics_to(
            self._thermal_profile, rs_extrinsics(rs, calibration)
        )
        self._device.create_matcher(rs.matchers.default)
        self._syncer = rs.syncer()
        self._depth_sensor.open(self._depth_profile)
        self._thermal_sensor.open(self._thermal_profile)
        self._depth_sensor.start(self._syncer)
        self._thermal_sensor.start(self._syncer)
        self._to_thermal = rs.align(rs.stream.infrared)
        self._to_depth = rs.align(rs.stream.depth)
        self._blank_thermal = np.zeros(t.shape, dtype=np.uint16)
        self._frame_number = 0
        self._open = True
        self._prime()

    def _stream(self, kind: Any, uid: int, fmt: Any, intr: Intrinsics, model: Any) -> Any:
        rs = self._rs
        s = rs.video_stream()
        s.type, s.index, s.uid = kind, uid, uid
        s.width, s.height, s.fps, s.bpp, s.fmt = intr.width, intr.height, self.FPS, 2, fmt
        i = rs.intrinsics()
        i.width, i.height = intr.width, intr.height
        # librealsense's pixel coordinates are OpenCV's: centre of the top-left pixel at 0, 0
        i.fx, i.fy, i.ppx, i.ppy = intr.fx, intr.fy, intr.cx, intr.cy
        i.model = model
        i.coeffs = [float(c) for c in intr.distortion]  # same order: k1, k2, p1, p2, k3
        s.intrinsics = i
        return s

    # -- per frame ---------------------------------------------------------------------------

    def _push(self, depth: NDArray[np.uint16], thermal: NDArray[np.uint16]) -> int:
        """Inject one frame pair (the pixels are copied) under a new frame number."""
        rs = self._rs
        self._frame_number += 1
        n = self._frame_number
        for sensor, profile, pixels in (
            (self._depth_sensor, self._depth_profile, depth),
            (self._thermal_sensor, self._thermal_profile, thermal),
        ):
            f = rs.software_video_frame()
            f.pixels = pixels
            f.bpp = 2
            f.stride = pixels.shape[1] * 2
            f.timestamp = n * 1000.0 / self.FPS
            f.domain = rs.timestamp_domain.hardware_clock
            f.frame_number = n
            f.profile = profile
            if sensor is self._depth_sensor:
                f.depth_units = self.calibration.depth_scale_m
            sensor.on_video_frame(f)
        return n

    def _wait(self, n: int, timeout_ms: int) -> Any:
        """The syncer's frameset holding both frames number ``n``, None on timeout; older or
        incomplete sets are dropped."""
        rs = self._rs
        while True:
            ok, frames = self._syncer.try_wait_for_frames(timeout_ms)
            if not ok:
                return None
            numbers = {f.profile.stream_type(): f.frame_number for f in frames}
            if numbers.get(rs.stream.depth) == n and numbers.get(rs.stream.infrared) == n:
                return frames

    def _prime(self) -> None:
        # The syncer drops the very first depth frame (its matcher learns the stream from it)
        # and hands out the first thermal frame alone: feed blank pairs until one comes out
        # whole, so that every timed call gets its frameset at once.
        depth = np.zeros(self.calibration.depth.shape, dtype=np.uint16)
        for _ in range(5):
            if self._wait(self._push(depth, self._blank_thermal), 200) is not None:
                return
        raise RuntimeError("rs.syncer never paired the depth and thermal streams")

    def _feed(self, depth: NDArray[np.uint16], thermal: NDArray[np.uint16]) -> Any:
        """Inject one frame pair and return the frameset the syncer makes of it."""
        n = self._push(depth, thermal)
        frames = self._wait(n, self.TIMEOUT_MS)
        if frames is None:
            raise RuntimeError(f"rs.syncer gave no frameset for frame {n}")
        return frames

    def _check(self, depth: NDArray[np.uint16], thermal: NDArray[np.uint16] | None) -> None:
        if not self._open:
            raise RuntimeError("RsAlign is closed")
        d, t = self.calibration.depth, self.calibration.thermal
        if depth.dtype != np.uint16 or depth.shape != d.shape or not depth.flags.c_contiguous:
            raise ValueError(
                f"depth must be C-contiguous uint16 {d.shape}, got {depth.dtype} {depth.shape}"
            )
        if thermal is not None and (
            thermal.dtype != np.uint16 or thermal.shape != t.shape or not thermal.flags.c_contiguous
        ):
            raise ValueError(
                f"thermal must be C-contiguous uint16 {t.shape}, got "
                f"{thermal.dtype} {thermal.shape}"
            )

    def depth_to_thermal(self, depth: NDArray[np.uint16]) -> NDArray[np.uint16]:
        """Depth on the thermal grid, (h, w) uint16 depth units, 0 where none lands.

        The smallest raw depth (Z in the depth camera's frame) among the depth pixels whose
        top-left corner projects into each thermal pixel. A blank thermal frame goes along:
        align needs both streams in the frameset.
        """
        self._check(depth, None)
        frames = self._feed(depth, self._blank_thermal)
        aligned = self._to_thermal.process(frames).get_depth_frame()
        return np.asanyarray(aligned.get_data()).copy()

    def thermal_to_depth(
        self, depth: NDArray[np.uint16], thermal: NDArray[np.uint16]
    ) -> NDArray[np.uint16]:
        """Thermal counts on the depth grid, (H, W) uint16, 0 where none (invalid depth or
        outside). The thermal pixel of each depth pixel's bottom-right corner; no occlusion
        test."""
        self._check(depth, thermal)
        frames = self._feed(depth, thermal)
        aligned = self._to_depth.process(frames)
        for f in aligned:
            if f.profile.stream_type() == self._rs.stream.infrared:
                return np.asanyarray(f.get_data()).copy()
        raise RuntimeError("rs.align returned no aligned thermal frame")

    def close(self) -> None:
        if self._open:
            self._open = False
            for sensor in (self._depth_sensor, self._thermal_sensor):
                sensor.stop()
                sensor.close()

    def __enter__(self) -> RsAlign:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def rs_extrinsics(rs: Any, calibration: Calibration, transpose: bool = False) -> Any:
    """``rs.extrinsics`` of ``thermal_from_depth``: rotation column-major (R^T row by row),
    translation in metres. ``transpose=True`` gives the classic mistake (R row-major, i.e.
    R^T applied) for the test that proves the convention."""
    tf = calibration.thermal_from_depth
    rot = tf.rotation if transpose else tf.rotation.T
    e = rs.extrinsics()
    e.rotation = [float(x) for x in rot.ravel()]
    e.translation = [float(x) for x in tf.translation_m]
    return e


# ---------------------------------------------------------------------------------------------
# OpenCV registerDepth
# ---------------------------------------------------------------------------------------------


def _register_depth_fn() -> Callable[..., NDArray[np.float32]]:
    import cv2

    fn = getattr(cv2, "registerDepth", None)  # OpenCV 5: module 3d, in every cv2 package
    if fn is None:  # OpenCV 4: opencv_contrib's rgbd module
        fn = getattr(getattr(cv2, "rgbd", None), "registerDepth", None)
    if fn is None:
        raise ImportError(
            f"cv2 {cv2.__version__} has no registerDepth: it needs OpenCV >= 5 (cv2.registerDepth) "
            "or opencv-contrib-python 4.x (cv2.rgbd.registerDepth)"
        )
    return fn


def register_depth_cv2(
    calibration: Calibration, depth: NDArray[np.uint16], origin: tuple[int, int] = (0, 0)
) -> NDArray[np.float32]:
    """Depth on the thermal grid by ``cv2.registerDepth``: (h, w) float32, Z in the thermal
    frame (metres), NaN where no depth pixel lands.

    registerDepth segfaults when the output plane is smaller than the depth image
    (opencv_contrib issue 3761), so it draws into a plane at least the depth image's size and
    the thermal image is cut out of it at ``origin`` = (x0, y0): pixel (u, v) of the plane is
    pixel (u - x0, v - y0) of the thermal image, i.e. the plane's principal point is the
    thermal one shifted by (x0, y0). Integer offsets keep both pixel grids aligned;
    distortion acts on normalised coordinates, so it is unaffected. The default (0, 0) keeps
    the float32 pixel coordinates small (a far origin flips a few border ties).

    The depth goes in as float32 metres (registerDepth reads uint16 as millimetres, whatever
    the depth unit, and would round the output to whole millimetres); 0 stays 0 = invalid.
    """
    d, t = calibration.depth, calibration.thermal
    if depth.dtype != np.uint16 or depth.shape != d.shape:
        raise ValueError(f"depth must be uint16 {d.shape}, got {depth.dtype} {depth.shape}")
    if d.has_distortion:
        raise ValueError("cv2.registerDepth cannot undistort the depth camera")
    x0, y0 = origin
    if x0 < 0 or y0 < 0:
        raise ValueError(f"origin must be >= 0, got {origin}")
    register = _register_depth_fn()
    k_plane = t.matrix.copy()
    k_plane[0, 2] += x0
    k_plane[1, 2] += y0
    plane = (max(d.width, x0 + t.width), max(d.height, y0 + t.height))  # (width, height)
    depth_m = np.multiply(depth, np.float32(calibration.depth_scale_m), dtype=np.float32)
    out = register(
        d.matrix,
        k_plane,
        np.asarray(t.distortion, dtype=np.float64),
        calibration.thermal_from_depth.matrix,  # 4x4: registerDepth reads Rt as a Matx44
        depth_m,
        plane,
        depthDilation=False,
    )
    return np.ascontiguousarray(out[y0 : y0 + t.height, x0 : x0 + t.width])


# ---------------------------------------------------------------------------------------------
# float64 numpy reference of thermodepth's "reproject" method
# ---------------------------------------------------------------------------------------------


def numpy_reference(
    calibration: Calibration,
    depth: NDArray[np.uint16],
    pixel_offset: tuple[float, float] = (0.0, 0.0),
) -> tuple[F64, F64, F64]:
    """Where every depth pixel lands in the thermal image, float64.

    Each depth pixel (u, v) with depth Z (``depth * depth_scale_m``) is deprojected through
    the depth intrinsics (undistorting), moved by ``thermal_from_depth`` and projected
    through the thermal lens (OpenCV distortion, refused beyond the radius where it folds).
    ``pixel_offset`` deprojects (u + du, v + dv) instead of the pixel centre, e.g.
    (0.5, 0.5) for librealsense's bottom-right corner.

    Returns (thermal_u, thermal_v, z), each (H, W) float64: continuous thermal pixel
    coordinates (centres at integers) and Z along the thermal optical axis in metres; all
    three NaN where the depth is 0, the point cannot be projected, or it falls outside the
    thermal image ([-0.5, w - 0.5) x [-0.5, h - 0.5)).
    """
    d, t = calibration.depth, calibration.thermal
    u, v = d.pixel_grid()
    pixels = np.stack([u + pixel_offset[0], v + pixel_offset[1]], axis=-1)
    z_d = depth.astype(np.float64) * calibration.depth_scale_m
    points = calibration.thermal_from_depth.apply(d.deproject(pixels, z_d))
    uv = t.project(points)
    bad = (depth == 0) | ~t.contains(uv)  # NaN pixels (not projectable) fail contains()
    thermal_u, thermal_v, z = uv[..., 0], uv[..., 1], points[..., 2]
    for a in (thermal_u, thermal_v, z):
        a[bad] = np.nan
    return thermal_u, thermal_v, z


def nearest_index(
    calibration: Calibration, thermal_u: F64, thermal_v: F64
) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """Flat index (v * w + u) of the nearest thermal pixel and where it exists."""
    w = calibration.thermal.width
    ok = np.isfinite(thermal_u)
    iu = np.floor(np.where(ok, thermal_u, 0.0) + 0.5).astype(np.intp)
    iv = np.floor(np.where(ok, thermal_v, 0.0) + 0.5).astype(np.intp)
    return np.where(ok, iv * w + iu, -1), ok


def reference_depth_to_thermal(
    calibration: Calibration,
    depth: NDArray[np.uint16],
    projected: tuple[F64, F64, F64] | None = None,
) -> F64:
    """The z-buffer: nearest Z (thermal frame, metres) per thermal pixel among the depth
    pixels whose projection rounds to it, (h, w) float64, NaN where none lands.

    ``projected``: :func:`numpy_reference` of this depth frame, if already computed.
    """
    thermal_u, thermal_v, z = projected or numpy_reference(calibration, depth)
    idx, ok = nearest_index(calibration, thermal_u, thermal_v)
    zbuf = np.full(calibration.thermal.width * calibration.thermal.height, np.inf)
    np.minimum.at(zbuf, idx[ok], z[ok])
    zbuf[np.isinf(zbuf)] = np.nan
    return zbuf.reshape(calibration.thermal.shape)


ToleranceM = float | Callable[[F64], F64]


def registration_tolerance(
    calibration: Calibration, tolerance: OcclusionTolerance | None = None
) -> Callable[[F64], F64]:
    """The occlusion tolerance of :class:`thermodepth.registration.Registration` as a
    function of Z in the thermal frame (metres): n_sigma sigma_z(Z) + slope Z / fx_thermal
    with sigma_z = Z^2 subpixel / (fx_depth baseline) (``OcclusionTolerance``)."""
    a, b = (tolerance or OcclusionTolerance()).coefficients(calibration)

    def tolerance_m(z: F64) -> F64:
        return a * z * z + b * z

    return tolerance_m


def reference_thermal_to_depth(
    calibration: Calibration,
    depth: NDArray[np.uint16],
    thermal: NDArray[np.generic],
    tolerance_m: ToleranceM,
    projected: tuple[F64, F64, F64] | None = None,
    zbuffer: F64 | None = None,
) -> tuple[F64, NDArray[np.uint8]]:
    """The thermal value seen at every depth pixel, nearest neighbour, with occlusion test.

    A depth pixel is occluded when its Z (thermal frame) exceeds the z-buffer of its thermal
    pixel by more than ``tolerance_m`` (metres; a number, or a function of that Z such as
    :func:`registration_tolerance`). Returns values (H, W) float64, NaN where the reason is
    not OK, and the reason (H, W) uint8 with :class:`thermodepth.registration.Reason` codes.
    ``projected``/``zbuffer``: :func:`numpy_reference` / :func:`reference_depth_to_thermal`
    of this depth frame, if already computed.
    """
    projected = projected or numpy_reference(calibration, depth)
    thermal_u, thermal_v, z = projected
    if zbuffer is None:
        zbuffer = reference_depth_to_thermal(calibration, depth, projected)
    idx, ok = nearest_index(calibration, thermal_u, thermal_v)
    taken = np.where(ok, idx, 0)
    zb = zbuffer.ravel()[taken]
    tol = tolerance_m(z) if callable(tolerance_m) else tolerance_m
    occluded = ok & (z > zb + tol)
    values = np.asarray(thermal, dtype=np.float64).ravel()[taken]
    values[~ok | occluded] = np.nan
    reason = np.full(depth.shape, Reason.OK, dtype=np.uint8)
    reason[~ok] = Reason.OUTSIDE
    reason[occluded] = Reason.OCCLUDED
    reason[depth == 0] = Reason.INVALID_DEPTH
    return values, reason


def thermal_index_image(cal: Calibration) -> NDArray[np.uint16]:
    """1 + the flat index of every thermal pixel: tells which pixel a sampler took (0 = none)."""
    t = cal.thermal
    return (np.arange(t.width * t.height) + 1).astype(np.uint16).reshape(t.shape)


def near_pixel_border(thermal_u: F64, thermal_v: F64, eps_px: float = 1e-3) -> NDArray[np.bool_]:
    """True where a thermal coordinate lies within ``eps_px`` of a pixel border (borders at
    k - 0.5, the image edges included): float32 and float64 may round these either way."""
    out = np.zeros(thermal_u.shape, dtype=bool)
    for c in (thermal_u, thermal_v):
        with np.errstate(invalid="ignore"):
            frac = np.mod(c + 0.5, 1.0)
            out |= (frac < eps_px) | (frac > 1.0 - eps_px)
    return out


def border_exclusions(
    calibration: Calibration, projected: tuple[F64, F64, F64], eps_px: float = 1e-3
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Where float32 kernels may legitimately differ from the float64 reference.

    Returns (depth_mask (H, W), thermal_mask (h, w)): the depth pixels whose reference thermal
    coordinate lies within ``eps_px`` of a pixel border (:func:`near_pixel_border`), and the
    thermal pixels such a depth pixel may land in (either side of the border), whose z-buffer
    may therefore differ.
    """
    thermal_u, thermal_v, _ = projected
    tie = near_pixel_border(thermal_u, thermal_v, eps_px)
    t = calibration.thermal
    thermal_mask = np.zeros(t.width * t.height, dtype=bool)
    tu, tv = thermal_u[tie], thermal_v[tie]
    for du in (-eps_px, eps_px):
        for dv in (-eps_px, eps_px):
            uv = np.stack([tu + du, tv + dv], axis=-1)
            inside = t.contains(uv)
            idx, _ = nearest_index(calibration, uv[inside, 0], uv[inside, 1])
            thermal_mask[idx] = True
    return tie, thermal_mask.reshape(t.shape)


def depth_to_thermal_agreement(
    z_a: NDArray[np.floating],
    z_b: NDArray[np.floating],
    exclude: NDArray[np.bool_] | None = None,
    rtol: float = 1e-5,
) -> float:
    """Fraction of thermal pixels (not excluded) where both z-buffers are NaN or agree within
    ``rtol`` (relative): 1e-5 is float32 rounding of Z through the projection."""
    a = np.asarray(z_a, dtype=np.float64)
    b = np.asarray(z_b, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        same = (np.isnan(a) & np.isnan(b)) | (np.abs(a - b) <= rtol * np.abs(b))
    keep = np.ones(a.shape, dtype=bool) if exclude is None else ~exclude
    return float(same[keep].mean())


def thermal_to_depth_agreement(
    values_a: NDArray[np.floating],
    reason_a: NDArray[np.uint8],
    values_b: NDArray[np.floating],
    reason_b: NDArray[np.uint8],
    exclude: NDArray[np.bool_] | None = None,
) -> float:
    """Fraction of depth pixels (not excluded) with the same reason and the same value (both
    NaN where the reason is not OK)."""
    a = np.asarray(values_a, dtype=np.float64)
    b = np.asarray(values_b, dtype=np.float64)
    same = (reason_a == reason_b) & ((a == b) | (np.isnan(a) & np.isnan(b)))
    keep = np.ones(a.shape, dtype=bool) if exclude is None else ~exclude
    return float(same[keep].mean())


def depth_frame_z(calibration: Calibration, z_thermal: NDArray[np.floating]) -> F64:
    """Z in the *depth* camera's frame of the point at Z = ``z_thermal`` (thermal frame) on
    the ray of each thermal pixel's centre, (h, w) float64: what ``rs.align`` reports per
    thermal pixel, to compare it with our ``DepthOnThermal.z_m``."""
    t = calibration.thermal
    u, v = t.pixel_grid()
    points = t.deproject(np.stack([u, v], axis=-1), np.asarray(z_thermal, dtype=np.float64))
    return calibration.thermal_from_depth.inverse().apply(points)[..., 2]


def without_thermal_distortion(cal: Calibration) -> Calibration:
    """The same rig with a distortion-free thermal lens (the peers' other benchmark case)."""
    return replace(cal, thermal=replace(cal.thermal, distortion=np.zeros(5)))
