"""A FLIR Lepton 3 on a GroupGets PureThermal board, over UVC (Video4Linux), with telemetry.

The PureThermal delivers Y16 frames of 160x122 when the Lepton's telemetry is enabled: the
160x120 image of raw 14-bit counts (radiometry on, AGC off) and two telemetry rows, which it
places last (footer). OpenCV's VideoCapture reads them as they are: FOURCC ``Y16 ``, RGB
conversion off (some OpenCV builds hand the buffer over as bytes; it is viewed as uint16).
Each frame is stamped with ``time.time()`` when it arrives (the host clock librealsense's
global time uses) and its telemetry decoded (:mod:`.telemetry`); a frame whose telemetry
cannot be decoded is skipped and counted (``bad_frames``). Frames taken while the shutter is
closed (FFC in progress) keep ``telemetry.in_ffc`` set: they are recorded, and a measuring
pipeline must leave them out.

Devices are found through sysfs (:func:`list_purethermal`): ``/sys/class/video4linux/video*``
whose name says PureThermal or whose USB vendor:product is GroupGets' 1e4e:0100.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..errors import InputError
from ..frames import ThermalFrame
from .base import DeviceLostError
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


class LeptonCamera:
    """Thermal frames from a Lepton 3 on a PureThermal board.

    index: the /dev/videoN number (default: the first PureThermal found); location: where the
    telemetry rows sit (PureThermal: ``"footer"``); timeout_s: silence that counts as
    unplugged. Raises InputError when no device is found (naming the video devices there are)
    or when the frames are not 160x122 Y16 (saying so).
    """

    def __init__(
        self,
        index: int | None = None,
        location: TelemetryLocation = "footer",
        timeout_s: float = 3.0,
        sysfs: Path = SYSFS_VIDEO,
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
        self.name = f"lepton:{index}"
        self.live = True
        self.bad_frames = 0
        self.cap = cv2.VideoCapture(index, cv2.CAP_V4L2)
        if not self.cap.isOpened():
            raise InputError(f"/dev/video{index}: cannot open (no such device, or busy)")
        self.cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*"Y16 "))
        self.cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
        self.cap.set(cv2.CAP_PROP_FRAME_WIDTH, FRAME_SHAPE[1])
        self.cap.set(cv2.CAP_PROP_FRAME_HEIGHT, FRAME_SHAPE[0])
        self.settings = {"device": f"/dev/video{index}", "telemetry_location": location}
        self._closed = False

    def __iter__(self) -> Iterator[ThermalFrame]:
        n = 0
        last_ok = time.monotonic()
        while not self._closed:
            ok, raw = self.cap.read()
            now = time.time()
            if not ok or raw is None:
                if self._closed:
                    return
                if time.monotonic() - last_ok > self.timeout_s or not self.cap.isOpened():
                    raise DeviceLostError(f"{self.name}: stopped delivering frames (unplugged?)")
                time.sleep(0.01)
                continue
            last_ok = time.monotonic()
            frame = frame_words(raw)
            image, words = split_frame(frame, self.location)  # InputError: wrong format
            try:
                telemetry = parse_telemetry(words)
            except TelemetryError:
                self.bad_frames += 1
                continue
            yield ThermalFrame(np.ascontiguousarray(image), now, n, telemetry)
            n += 1

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.cap.release()
