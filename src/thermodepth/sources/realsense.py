"""Intel RealSense depth through pyrealsense2: a live camera or a recorded file.

Live: any Z16 depth mode (``--depth-mode 848x480@30``); by default the one Intel recommends for
the camera: 848x480 at 30 fps on the D435, D435i, D455 and D405 (their 1280x720 is
interpolated from the 1280x800 imagers and measures no better: librealsense issue 11180,
Intel's "Tuning depth cameras for best performance"), 1280x720 on the D415. Optionally the
left infrared imager at the same mode (Y8, pixel-aligned with depth). Files: librealsense
recordings, ROS1 ``.bag`` (what librealsense wrote up to 2.5x) or rosbag2 ``.db3`` (what
pyrealsense2 2.59 writes), of any depth mode, played back as fast as they are read
(non-real-time: no frame is skipped).

At the edge: the device's depth intrinsics and depth unit (metres per Z16 count, read from the
device, never assumed: a D405 counts 0.1 mm) go into the calibration (:func:`depth_section`,
:func:`~.base.with_device_depth`) and, always, into recordings (``device_depth``); frame
timestamps in milliseconds become seconds.
Live frames carry librealsense's global time (host clock, ms since the epoch), which is the
clock the Lepton source stamps its frames with (``time.time()``); frames of a hardware clock
domain are stamped with their host arrival time instead.
"""

from __future__ import annotations

import contextlib
import queue
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..calibration import camera_dict
from ..camera import Intrinsics
from ..errors import InputError, ThermodepthError
from ..frames import DepthFrame
from .base import DeviceGuard, DeviceLostError

DEPTH_FPS = 30
PLAYBACK_EXTENSIONS = (".bag", ".db3")
FILE_QUEUE = 4
"""A file's frames played ahead of the reader, at most (the file waits for it)."""
DEFAULT_MODES = {"D415": (1280, 720, 30)}
"""The default depth mode of the cameras whose best is not 848x480 at 30 fps (by the model
in the device's name)."""
RECOMMENDED_MODE = (848, 480, 30)


def default_mode(device_name: str) -> tuple[int, int, int]:
    """The depth mode thermodepth opens a camera in unless told: Intel's recommended one
    (848x480 at 30 fps; 1280x720 on a D415)."""
    return next(
        (mode for model, mode in DEFAULT_MODES.items() if model in device_name), RECOMMENDED_MODE
    )


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


def check_playback_file(path: Path) -> None:
    """A librealsense recording that exists (.bag or .db3), or one InputError line."""
    if path.suffix.lower() not in PLAYBACK_EXTENSIONS:
        raise InputError(
            f"{path}: expected a RealSense recording (.bag or .db3), "
            f"got {path.suffix or 'no extension'}"
        )
    if not path.is_file():
        raise InputError(f"{path}: no such file")


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


def depth_section(depth: Intrinsics, depth_scale_m: float) -> dict[str, Any]:
    """The device's depth intrinsics (pixels) and depth unit (metres per Z16 count) as a
    calibration file's ``depth`` section (see :func:`~.base.with_device_depth`)."""
    return {**camera_dict(depth), "depth_scale_m": float(depth_scale_m)}


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
    mode: the depth mode (width, height, fps; None: the camera's recommended one,
    :func:`default_mode`, or a file's own; a file whose depth stream differs from a mode
    given is refused with both named); with_ir: also read the left infrared imager;
    timeout_s: a live camera that delivers no new frame for this long counts as unplugged;
    warn: where the one warning about a restarted stream goes (default: ``warnings.warn``).
    After opening: ``intrinsics`` (depth), ``depth_scale_m``, ``serial``, ``live``,
    ``device_depth``. Anything failing after the pipeline started stops it again and raises
    a one-line InputError.

    Iterating yields each new depth frame once: a frameset repeating the last frame number
    (the pipeline's syncer does so when only the IR image is new) is skipped; a frame number
    lower than the last means the stream restarted (librealsense restarts the pipeline after
    a USB reconnect): it is taken, warned about once and counted (``restarts``). With
    ``with_ir``, a frameset without an IR image is skipped and counted (``missing_ir``); the
    depth frame is taken if a later frameset brings it with its IR image.
    ``close()`` may be called from any thread (see :class:`~.base.DeviceGuard`).
    """

    def __init__(
        self,
        serial: str | None = None,
        path: str | Path | None = None,
        mode: tuple[int, int, int] | None = None,
        with_ir: bool = False,
        timeout_s: float = 5.0,
        warn: Callable[[str], None] | None = None,
    ) -> None:
        if path is not None:  # a file that cannot be played says so, pyrealsense2 or not
            check_playback_file(Path(path))
        rs = self.rs = import_realsense()
        self.mode, self.with_ir, self.timeout_s = mode, with_ir, timeout_s
        self.warn = warn or (lambda msg: warnings.warn(msg, stacklevel=2))
        self.path = None if path is None else Path(path)
        self.live = self.path is None
        self.restarts = 0
        self.missing_ir = 0
        self._last_number = -1
        self._closing = threading.Event()
        self._played: queue.Queue[Any] = queue.Queue(FILE_QUEUE)
        self._sensor: Any = None
        self._held: Any = None  # a file's depth frame waiting for its IR image
        self._irs: dict[int, Any] = {}  # a file's latest IR images by frame number
        self.pipeline = rs.pipeline()
        self.name = f"realsense:{self.path}" if self.path is not None else "realsense"
        profile = self._start_live(serial) if self.path is None else self._start_file(self.path)
        try:
            self._describe(profile)
        except BaseException as exc:
            with contextlib.suppress(RuntimeError):
                self.pipeline.stop()
            if isinstance(exc, RuntimeError):
                raise InputError(f"{self.name}: cannot read the stream's profile ({exc})") from None
            raise
        self._guard = DeviceGuard(self._stop)

    def _start_file(self, path: Path) -> Any:
        # a file plays at the pace its frames are read, none dropped: its sensor (not the
        # pipeline, whose queues keep only the newest frames) hands each frame to _deliver,
        # which waits while the reader is behind, and the device is told before it starts
        rs = self.rs
        try:
            device = rs.context().load_device(str(path))
            device.as_playback().set_real_time(False)
            kinds = (rs.stream.depth, rs.stream.infrared)
            sensor = next(
                (s for s in device.query_sensors()
                 if any(p.stream_type() == rs.stream.depth for p in s.get_stream_profiles())),
                device.query_sensors()[0],
            )  # fmt: skip
            profiles = [
                p
                for p in sensor.get_stream_profiles()
                if p.stream_type() in kinds
                and (p.stream_type() == rs.stream.depth or p.stream_index() in (0, 1))
            ]
            sensor.open(profiles)
            sensor.start(self._deliver)
        except (RuntimeError, IndexError) as exc:
            raise InputError(f"{path}: cannot play this file ({exc})") from None
        self._sensor = sensor
        return _FileProfile(device, profiles)

    def _deliver(self, frame: Any) -> None:
        """A file's frame (librealsense's thread), queued for the reader; the file waits."""
        frame.keep()
        while not self._closing.is_set():
            try:
                self._played.put(frame, timeout=0.1)
                return
            except queue.Full:
                continue

    def _next_played(self, timeout_ms: int) -> tuple[bool, Any]:
        """A file's next depth frame, with the IR image of the same number when it has one
        (as the pipeline's syncer pairs a live camera's)."""
        rs = self.rs
        while True:
            try:
                frame = self._played.get(timeout=timeout_ms / 1000)
            except queue.Empty:
                if self._held is not None and self._playback.current_status() == (
                    rs.playback_status.stopped
                ):
                    held, self._held = self._held, None
                    return True, _FileFrames(held, None)
                return False, None
            number = frame.get_frame_number()
            if frame.get_profile().stream_type() == rs.stream.infrared:
                self._irs = {**{k: v for k, v in self._irs.items() if k >= number - 2},
                             number: frame}  # fmt: skip
                if self._held is not None and self._held.get_frame_number() == number:
                    held, self._held = self._held, None
                    return True, _FileFrames(held, frame)
                continue
            held, self._held = self._held, None
            if held is not None:  # its IR never came: the reader counts it
                self._held = frame
                return True, _FileFrames(held, self._irs.get(held.get_frame_number()))
            if not self.with_ir or number in self._irs:
                return True, _FileFrames(frame, self._irs.get(number))
            self._held = frame

    def _start_live(self, serial: str | None) -> Any:
        rs = self.rs
        attached = list_realsense()
        if not attached:
            raise InputError("no RealSense device found (is it plugged in?)")
        if serial and serial not in [d["serial"] for d in attached]:
            there = ", ".join(f"{d['name']} {d['serial']}" for d in attached)
            raise InputError(f"no RealSense device with serial {serial} (found: {there})")
        config = rs.config()
        if serial:
            config.enable_device(serial)
            self.name = f"realsense:{serial}"
        device = next(d for d in attached if not serial or d["serial"] == serial)
        self.mode = self.mode or default_mode(device["name"])
        w, h, fps = self.mode
        config.enable_stream(rs.stream.depth, w, h, rs.format.z16, fps)
        if self.with_ir:
            config.enable_stream(rs.stream.infrared, 1, w, h, rs.format.y8, fps)
        try:
            return self.pipeline.start(config)
        except RuntimeError as exc:
            raise InputError(
                f"RealSense {device['name']} {device['serial']}: cannot stream depth {w}x{h} "
                f"Z16 at {fps} fps{' + IR Y8' if self.with_ir else ''} ({exc}); choose a mode "
                "it offers (--depth-mode WxH@FPS; 848x480@30 for a D435 on USB 3)"
            ) from None

    def _describe(self, profile: Any) -> None:
        """Check a file's streams; read the serial, the mode, depth intrinsics and unit."""
        rs = self.rs
        device = profile.get_device()
        if self.path is not None:
            self._playback = device.as_playback()
            self._playback.set_real_time(False)
            streams = list(profile.get_streams())
            depth = [s for s in streams if s.stream_type() == rs.stream.depth]
            if not depth:
                there = ", ".join(_describe(s) for s in streams) or "no video streams"
                raise InputError(f"{self.path}: no depth stream in this recording (found {there})")
            vp = depth[0].as_video_stream_profile()
            mode = (vp.width(), vp.height(), int(depth[0].fps()))
            wanted = self.mode or mode
            if depth[0].format() != rs.format.z16 or mode[:2] != wanted[:2]:
                raise InputError(
                    f"{self.path}: expected depth {wanted[0]}x{wanted[1]} Z16, found "
                    f"{_describe(depth[0])}"
                )
            self.mode = mode
            self.with_ir = self.with_ir and any(
                s.stream_type() == rs.stream.infrared for s in streams
            )
        self.serial = device.get_info(rs.camera_info.serial_number)
        dp = profile.get_stream(rs.stream.depth).as_video_stream_profile()
        self.intrinsics = intrinsics_from_rs(dp.get_intrinsics())
        self.depth_scale_m = float(device.first_depth_sensor().get_depth_scale())
        self.device_depth = depth_section(self.intrinsics, self.depth_scale_m)
        assert self.mode is not None
        w, h, fps = self.mode
        self.settings = {
            "serial": self.serial,
            "depth": f"{w}x{h} Z16 at {fps} fps",
            "with_ir": self.with_ir,
            "depth_scale_m": self.depth_scale_m,
            **({"file": str(self.path)} if self.path else {}),
        }

    def counters(self) -> dict[str, int]:
        out = {"depth_restarts": self.restarts}
        if self.with_ir:
            out["depth_missing_ir"] = self.missing_ir
        return out

    def __iter__(self) -> Iterator[DepthFrame]:
        """The new depth frames until the file ends or the camera is closed; the pipeline is
        stopped when this ends."""
        timeout_ms = int(self.timeout_s * 1000)
        if not self.live:  # poll, so that the end of a file is noticed at once
            timeout_ms = 100
        last_new = time.monotonic()
        try:
            while True:
                with self._guard.reading() as open_:
                    if not open_:
                        return
                    try:
                        if self.live:
                            ok, frames = self.pipeline.try_wait_for_frames(timeout_ms)
                        else:
                            ok, frames = self._next_played(timeout_ms)
                    except RuntimeError as exc:
                        raise DeviceLostError(
                            f"{self.name}: stopped delivering frames ({exc})"
                        ) from None
                    frame = self._new_frame(frames) if ok else None
                if frame is not None:
                    last_new = time.monotonic()
                    yield frame
                elif self.live:
                    if time.monotonic() - last_new > self.timeout_s:
                        raise DeviceLostError(
                            f"{self.name}: no new frame for {self.timeout_s:g} s (unplugged?)"
                        )
                elif not ok and self._playback.current_status() == self.rs.playback_status.stopped:
                    return  # end of the file
        finally:
            self._guard.release()

    def _new_frame(self, frames: Any) -> DepthFrame | None:
        """The frameset's depth frame if it is new (see the class docstring), else None."""
        depth = frames.get_depth_frame()
        if not depth:
            return None
        number = int(depth.get_frame_number())
        if number == self._last_number:
            return None  # the syncer repeats a frame when only IR is new
        ir = None
        if self.with_ir:
            irf = frames.get_infrared_frame(1)
            if not irf:
                self.missing_ir += 1
                return None
            ir = np.array(np.asanyarray(irf.get_data()), dtype=np.uint8, copy=True)
        if number < self._last_number:
            self.restarts += 1
            if self.restarts == 1:
                self.warn(
                    f"{self.name}: frame number went back from {self._last_number} to {number}: "
                    "the stream restarted (as after a USB reconnect); going on (counted, "
                    "warned once)"
                )
        self._last_number = number
        return DepthFrame(
            np.array(np.asanyarray(depth.get_data()), dtype=np.uint16, copy=True),
            depth_time_s(self.rs, depth, self.live),
            number,
            ir,
        )

    def _stop(self) -> None:
        self._closing.set()  # a delivery waiting for room gives up: stop() waits for it
        with contextlib.suppress(RuntimeError):
            if self._sensor is None:
                self.pipeline.stop()
            else:
                self._sensor.stop()
                self._sensor.close()

    def close(self) -> None:
        """Stop streaming; the pipeline is stopped now, or by the reading thread as soon as
        its wait returns (never under a wait)."""
        self._guard.close()


class _FileProfile(NamedTuple):
    """What a pipeline's profile tells, for a file played through its sensor."""

    device: Any
    streams: list[Any]

    def get_device(self) -> Any:
        return self.device

    def get_streams(self) -> list[Any]:
        return self.streams

    def get_stream(self, kind: Any) -> Any:
        return next(s for s in self.streams if s.stream_type() == kind)


class _FileFrames(NamedTuple):
    """A file's depth frame and its IR image, as a pipeline's frameset gives them."""

    depth: Any
    ir: Any

    def get_depth_frame(self) -> Any:
        return self.depth

    def get_infrared_frame(self, index: int = 1) -> Any:
        return self.ir


def list_realsense() -> list[dict[str, str]]:
    """Attached RealSense devices: name, serial, firmware, USB type. Raises ThermodepthError
    (saying why) when pyrealsense2 cannot be imported."""
    rs = import_realsense()
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
