"""Intel RealSense depth through pyrealsense2: a live camera or a recorded file.

Live: depth 1280x720 Z16 at 30 fps (a D435's native mode), optionally the left infrared
imager (Y8, same size, pixel-aligned with depth). Files: librealsense recordings, ROS1 ``.bag``
(what librealsense wrote up to 2.5x) or rosbag2 ``.db3`` (what pyrealsense2 2.59 writes),
played back as fast as they are read (non-real-time: no frame is skipped).

At the edge: the device's depth intrinsics and depth unit (metres per Z16 count) go into the
calibration (:func:`depth_calibration`); frame timestamps in milliseconds become seconds.
Live frames carry librealsense's global time (host clock, ms since the epoch), which is the
clock the Lepton source stamps its frames with (``time.time()``); frames of a hardware clock
domain are stamped with their host arrival time instead.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..calibration import Calibration
from ..camera import Intrinsics
from ..errors import InputError, ThermodepthError
from ..frames import DepthFrame
from .base import DeviceLostError

DEPTH_SIZE = (1280, 720)
DEPTH_FPS = 30
PLAYBACK_EXTENSIONS = (".bag", ".db3")


def import_realsense() -> Any:
    """pyrealsense2, or a one-line error saying how to get it."""
    try:
        import pyrealsense2 as rs
    except ImportError as exc:
        raise ThermodepthError(
            f"pyrealsense2 is not available ({exc}); install thermodepth[realsense] "
            "(and the system library libusb-1.0-0)"
        ) from None
    return rs


def intrinsics_from_rs(intr: Any) -> Intrinsics:
    """librealsense intrinsics -> ours. librealsense's principal point ``ppx, ppy`` and focal
    lengths are in pixels with the same convention as OpenCV (pixel centres at integers);
    coefficients are [k1, k2, p1, p2, k3] for the Brown-Conrady models (a D435's depth stream
    reports zeros)."""
    return Intrinsics(
        int(intr.width),
        int(intr.height),
        float(intr.fx),
        float(intr.fy),
        float(intr.ppx),
        float(intr.ppy),
        np.asarray(list(intr.coeffs)[:5], dtype=np.float64),
    )


def depth_calibration(user: Calibration, depth: Intrinsics, depth_scale_m: float) -> Calibration:
    """The user's calibration with the device's depth intrinsics and depth unit.

    The thermal intrinsics and ``thermal_from_depth`` come from the user's file; a depth image
    size that differs from the file's is allowed (the device's wins), since the depth section
    describes the stream actually recorded.
    """
    return Calibration(depth, user.thermal, float(depth_scale_m), user.thermal_from_depth)


def _describe(profile: Any) -> str:
    vp = profile.as_video_stream_profile()
    return f"{profile.stream_name()} {vp.width()}x{vp.height()} {str(profile.format()).split('.')[-1].upper()} at {profile.fps()} fps"  # noqa: E501


def depth_time_s(rs: Any, frame: Any, live: bool = True) -> float:
    """A frame's capture time in seconds: its timestamp (ms) when it is on the host clock
    (global or system time) or comes from a file (replayed as recorded); for a live frame on
    the device's hardware clock, the host time now (it cannot be paired otherwise)."""
    domain = frame.get_frame_timestamp_domain()
    host = (rs.timestamp_domain.global_time, rs.timestamp_domain.system_time)
    if not live or domain in host:
        return float(frame.get_timestamp()) / 1000.0
    return time.time()


class RealSenseCamera:
    """Depth frames from a RealSense device or file, as :class:`~thermodepth.frames.DepthFrame`.

    serial: pick a device (default: the first); path: play a ``.bag`` / ``.db3`` file instead;
    size / fps: the depth mode expected (1280x720 at 30 by default; a file whose depth stream
    differs is refused with both named); with_ir: also read the left infrared imager;
    timeout_s: a live camera silent this long counts as unplugged.
    After opening: ``intrinsics`` (depth), ``depth_scale_m``, ``serial``, ``live``.
    """

    def __init__(
        self,
        serial: str | None = None,
        path: str | Path | None = None,
        size: tuple[int, int] = DEPTH_SIZE,
        fps: int = DEPTH_FPS,
        with_ir: bool = False,
        timeout_s: float = 5.0,
    ) -> None:
        rs = self.rs = import_realsense()
        self.size, self.fps, self.with_ir, self.timeout_s = size, fps, with_ir, timeout_s
        self.path = None if path is None else Path(path)
        self.live = self.path is None
        self.pipeline = rs.pipeline()
        config = rs.config()
        w, h = size
        if self.path is not None:
            self.name = f"realsense:{self.path}"
            if self.path.suffix.lower() not in PLAYBACK_EXTENSIONS:
                raise InputError(
                    f"{self.path}: expected a RealSense recording (.bag or .db3), "
                    f"got {self.path.suffix or 'no extension'}"
                )
            if not self.path.is_file():
                raise InputError(f"{self.path}: no such file")
            config.enable_device_from_file(str(self.path), repeat_playback=False)
            try:
                profile = self.pipeline.start(config)
            except RuntimeError as exc:
                raise InputError(f"{self.path}: cannot play this file ({exc})") from None
            self._playback = profile.get_device().as_playback()
            self._playback.set_real_time(False)
            streams = list(profile.get_streams())
            depth = [s for s in streams if s.stream_type() == rs.stream.depth]
            if not depth:
                self.pipeline.stop()
                found = ", ".join(_describe(s) for s in streams) or "no video streams"
                raise InputError(f"{self.path}: no depth stream in this recording (found {found})")
            vp = depth[0].as_video_stream_profile()
            got = (vp.width(), vp.height(), depth[0].format())
            if got != (w, h, rs.format.z16):
                self.pipeline.stop()
                raise InputError(
                    f"{self.path}: expected depth {w}x{h} Z16, found {_describe(depth[0])}"
                )
            self.with_ir = with_ir and any(s.stream_type() == rs.stream.infrared for s in streams)
            self.serial = profile.get_device().get_info(rs.camera_info.serial_number)
        else:
            attached = list_realsense()
            if not attached:
                raise InputError("no RealSense device found (is it plugged in?)")
            if serial and serial not in [d["serial"] for d in attached]:
                there = ", ".join(f"{d['name']} {d['serial']}" for d in attached)
                raise InputError(f"no RealSense device with serial {serial} (found: {there})")
            if serial:
                config.enable_device(serial)
            config.enable_stream(rs.stream.depth, w, h, rs.format.z16, fps)
            if with_ir:
                config.enable_stream(rs.stream.infrared, 1, w, h, rs.format.y8, fps)
            try:
                profile = self.pipeline.start(config)
            except RuntimeError as exc:
                raise InputError(
                    f"RealSense {serial or attached[0]['serial']}: cannot stream depth {w}x{h} Z16 "
                    f"at {fps} fps{' + IR Y8' if with_ir else ''} ({exc}); expected a D435-class "
                    "camera on USB 3"
                ) from None
            self.serial = profile.get_device().get_info(rs.camera_info.serial_number)
            self.name = f"realsense:{self.serial}" if serial else "realsense"
        dp = profile.get_stream(rs.stream.depth).as_video_stream_profile()
        self.intrinsics = intrinsics_from_rs(dp.get_intrinsics())
        self.depth_scale_m = float(profile.get_device().first_depth_sensor().get_depth_scale())
        self.settings = {
            "serial": self.serial,
            "depth": f"{w}x{h} Z16 at {fps} fps",
            "with_ir": self.with_ir,
            "depth_scale_m": self.depth_scale_m,
            **({"file": str(self.path)} if self.path else {}),
        }
        self._closed = False

    def __iter__(self) -> Iterator[DepthFrame]:
        rs = self.rs
        last = -1
        timeout_ms = int(self.timeout_s * 1000)
        if not self.live:  # poll, so that the end of a file is noticed at once
            timeout_ms = 100
        while not self._closed:
            try:
                ok, frames = self.pipeline.try_wait_for_frames(timeout_ms)
            except RuntimeError as exc:
                if self._closed:
                    return
                raise DeviceLostError(f"{self.name}: stopped delivering frames ({exc})") from None
            if not ok:
                if self._closed:
                    return
                if self.live:
                    raise DeviceLostError(
                        f"{self.name}: no frame for {self.timeout_s:g} s (unplugged?)"
                    )
                if self._playback.current_status() == self.rs.playback_status.stopped:
                    return  # end of the file
                continue
            depth = frames.get_depth_frame()
            if not depth:
                continue
            number = int(depth.get_frame_number())
            if number <= last:
                continue  # the pipeline's syncer repeats a frame when only IR is new
            last = number
            ir = None
            if self.with_ir:
                irf = frames.get_infrared_frame(1)
                if irf:
                    ir = np.array(np.asanyarray(irf.get_data()), dtype=np.uint8, copy=True)
            yield DepthFrame(
                np.array(np.asanyarray(depth.get_data()), dtype=np.uint16, copy=True),
                depth_time_s(rs, depth, self.live),
                number,
                ir,
            )

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            with contextlib.suppress(RuntimeError):
                self.pipeline.stop()


def list_realsense() -> list[dict[str, str]]:
    """Attached RealSense devices: name, serial, firmware, USB type ([] without
    pyrealsense2 or devices)."""
    try:
        rs = import_realsense()
    except ThermodepthError:
        return []
    out = []
    for dev in rs.context().query_devices():

        def info(key: Any, dev: Any = dev) -> str:
            return str(dev.get_info(key)) if dev.supports(key) else "?"

        out.append(
            {
                "name": info(rs.camera_info.name),
                "serial": info(rs.camera_info.serial_number),
                "firmware": info(rs.camera_info.firmware_version),
                "usb": info(rs.camera_info.usb_type_descriptor),
            }
        )
    return out
