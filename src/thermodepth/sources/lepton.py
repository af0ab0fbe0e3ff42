"""A FLIR Lepton 3 on a GroupGets PureThermal board, over UVC (Video4Linux), with telemetry.

The PureThermal delivers Y16 frames of 160x122 when the Lepton's telemetry is enabled: the
160x120 image of raw 14-bit counts (radiometry on, AGC off, TLinear off) and two telemetry
rows, which it places last (footer). OpenCV's VideoCapture reads them as they are: FOURCC
``Y16 ``, RGB conversion off, a one-frame buffer where the driver allows it (some OpenCV
builds hand the buffer over as bytes; it is viewed as uint16).

Timestamps: each frame is stamped with ``time.time()`` when ``read()`` returns it (the host
clock librealsense's global time uses), minus ``latency_s``: the time from exposure to
arrival (sensor readout, the PureThermal's USB transfer, driver buffering). It defaults to 0
because it has not been measured; a measured value moves every thermal time by that much.

Telemetry is decoded per frame (:mod:`.telemetry`). A frame whose telemetry cannot be decoded
is skipped and counted (``bad_frames``); when none decodes for ``telemetry_timeout_s`` (2 s)
the camera stops with one line naming the likely cause (telemetry disabled, or in the other
location). Frames with TLinear on (kelvin x 100, not counts) are refused. Frames taken while
the shutter is closed (FFC in progress) keep ``telemetry.in_ffc`` set: they are recorded, and
a measuring pipeline must leave them out.

Devices are found through sysfs (:func:`list_purethermal`): ``/sys/class/video4linux/video*``
whose name says PureThermal or whose USB vendor:product is GroupGets' 1e4e:0100.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..errors import InputError
from ..frames import ThermalFrame
from .base import DeviceGuard, DeviceLostError
from .telemetry import FRAME_SHAPE, TelemetryError, TelemetryLocation, parse_telemetry, split_frame

PURETHERMAL_USB_IDS = {("1e4e", "0100")}
"""GroupGets PureThermal 1/2/mini (USB vendor, product)."""
SYSFS_VIDEO = Path("/sys/class/video4linux")


def _read(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8", errors="replace").strip()
    except OSError:
        return ""


def list_video_devices(sysfs: Path = SYSFS_VIDEO) -> list[dict[str, Any]]:
    """Every V4L2 capture node: ``index`` (N of /dev/videoN), ``name``, ``usb_id`` (vendor,
    product or None), ``purethermal`` (bool). Nodes with sysfs ``index`` > 0 (the metadata
    nodes UVC devices add) are left out. Robust to missing or unreadable sysfs files."""
    out = []
    try:
        nodes = sorted(sysfs.glob("video*"), key=lambda p: int(p.name[5:] or 0))
    except (OSError, ValueError):
        return []
    for node in nodes:
        if not node.name[5:].isdigit():
            continue
        if _read(node / "index") not in ("", "0"):
            continue
        name = _read(node / "name")
        usb_id = None
        dev = node / "device"
        for parent in (dev, dev / "..", dev / "../.."):
            vendor, product = _read(parent / "idVendor"), _read(parent / "idProduct")
            if vendor:
                usb_id = (vendor.lower(), product.lower())
                break
        out.append(
            {
                "index": int(node.name[5:]),
                "name": name,
                "usb_id": usb_id,
                "purethermal": "purethermal" in name.lower() or usb_id in PURETHERMAL_USB_IDS,
            }
        )
    return out


def list_purethermal(sysfs: Path = SYSFS_VIDEO) -> list[dict[str, Any]]:
    """The video devices that look like a PureThermal board."""
    return [d for d in list_video_devices(sysfs) if d["purethermal"]]


def frame_words(raw: Any) -> np.ndarray:
    """OpenCV's Y16 buffer as a (rows, 160) uint16 frame: some builds return (122, 160)
    uint16, others the raw bytes as (1, N) or (N, 1) uint8."""
    arr = np.asarray(raw)
    if arr.dtype == np.uint8 and arr.size == FRAME_SHAPE[0] * FRAME_SHAPE[1] * 2:
        return arr.reshape(-1).view("<u2").reshape(FRAME_SHAPE).astype(np.uint16)
    return arr


@contextmanager
def quiet_opencv() -> Iterator[None]:
    """OpenCV's own log lines (``[ WARN ] ... can't open camera by index``) off: the
    errors raised say what went wrong in one line."""
    log = getattr(getattr(cv2, "utils", None), "logging", None)
    if log is None:
        yield
        return
    old = log.setLogLevel(log.LOG_LEVEL_SILENT)
    try:
        yield
    finally:
        log.setLogLevel(old)


class LeptonCamera:
    """Thermal frames from a Lepton 3 on a PureThermal board.

    index: the /dev/videoN number (default: the first PureThermal found); location: where the
    telemetry rows sit (PureThermal: ``"footer"``); timeout_s: silence that counts as
    unplugged; telemetry_timeout_s: how long frames may come without decodable telemetry
    before the camera stops (InputError); latency_s: subtracted from each frame's arrival
    time (see the module docstring; 0 = not calibrated). Raises InputError when no device is
    found (naming the video devices there are), when the device cannot be opened, and, while
    iterating, when the frames are not 160x122 Y16 or carry TLinear values.
    ``close()`` may be called from any thread (see :class:`~.base.DeviceGuard`).
    """

    def __init__(
        self,
        index: int | None = None,
        location: TelemetryLocation = "footer",
        timeout_s: float = 3.0,
        sysfs: Path = SYSFS_VIDEO,
        telemetry_timeout_s: float = 2.0,
        latency_s: float = 0.0,
    ) -> None:
        if index is None:
            found = list_purethermal(sysfs)
            if not found:
                others = ", ".join(
                    f"/dev/video{d['index']} ({d['name'] or 'unnamed'})"
                    for d in list_video_devices(sysfs)
                )
                raise InputError(
                    "no PureThermal (Lepton) found"
                    + (f"; video devices: {others}" if others else "; no video devices at all")
                )
            index = int(found[0]["index"])
        self.index = index
        self.location = location
        self.timeout_s = timeout_s
        self.telemetry_timeout_s = telemetry_timeout_s
        self.latency_s = latency_s
        self.name = f"lepton:{index}"
        self.live = True
        self.bad_frames = 0
        device = Path(f"/dev/video{index}")
        with quiet_opencv():
            self.cap = cv2.VideoCapture(index, cv2.CAP_V4L2)
            if not self.cap.isOpened():
                why = "busy, or not a capture device" if device.exists() else "no such device"
                raise InputError(f"{device}: cannot open ({why})")
            self.cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*"Y16 "))
            self.cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
            self.cap.set(cv2.CAP_PROP_FRAME_WIDTH, FRAME_SHAPE[1])
            self.cap.set(cv2.CAP_PROP_FRAME_HEIGHT, FRAME_SHAPE[0])
            self.cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)  # the newest frame, not a queued one
        self.settings = {
            "device": str(device),
            "telemetry_location": location,
            "latency_s": latency_s,
        }
        self._guard = DeviceGuard(self.cap.release)

    def counters(self) -> dict[str, int]:
        return {"thermal_bad_telemetry": self.bad_frames}

    def __iter__(self) -> Iterator[ThermalFrame]:
        """The camera's frames until it is closed; the camera is released when this ends."""
        n = 0
        last_ok = time.monotonic()
        bad_since: float | None = None
        try:
            while True:
                with self._guard.reading() as open_:
                    if not open_:
                        return
                    ok, raw = self.cap.read()
                    now = time.time() - self.latency_s
                    got = ok and raw is not None
                    silent = time.monotonic() - last_ok > self.timeout_s
                    lost = not got and (silent or not self.cap.isOpened())
                if lost:
                    raise DeviceLostError(f"{self.name}: stopped delivering frames (unplugged?)")
                if not got:
                    time.sleep(0.01)
                    continue
                last_ok = time.monotonic()
                frame = frame_words(raw)
                image, words = split_frame(frame, self.location)  # InputError: wrong format
                try:
                    telemetry = parse_telemetry(words)
                except TelemetryError as exc:
                    self.bad_frames += 1
                    bad_since = last_ok if bad_since is None else bad_since
                    if last_ok - bad_since > self.telemetry_timeout_s:
                        raise InputError(self._no_telemetry(frame, exc)) from None
                    continue
                bad_since = None
                if telemetry.tlinear:
                    raise InputError(
                        f"{self.name}: TLinear output is on (pixels are kelvin x "
                        f"{1 / (telemetry.tlinear_resolution_k or 0.01):g}, not raw counts); "
                        "thermodepth needs raw counts: turn TLinear off (Lepton SDK: RAD "
                        "TLinear enable state = disabled)"
                    )
                yield ThermalFrame(np.ascontiguousarray(image), now, n, telemetry)
                n += 1
        finally:
            self._guard.release()

    def _no_telemetry(self, frame: np.ndarray, exc: TelemetryError) -> str:
        """The one line for frames without telemetry: where it is, or what to check."""
        other: TelemetryLocation = "header" if self.location == "footer" else "footer"
        try:
            parse_telemetry(split_frame(frame, other)[1])
        except TelemetryError:
            return (
                f"{self.name}: no frame with valid telemetry for {self.telemetry_timeout_s:g} s "
                f"({self.bad_frames} frames; last: {exc}); enable the Lepton's telemetry, as a "
                f"{self.location}"
            )
        return (
            f"{self.name}: the telemetry rows are in the {other}, not the {self.location}: "
            f"open the camera with location={other!r}"
        )

    def close(self) -> None:
        """Stop reading; the device is released now, or by the reading thread as soon as its
        read returns (never under a read)."""
        self._guard.close()
