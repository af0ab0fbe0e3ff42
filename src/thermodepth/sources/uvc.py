"""Thermal cameras over UVC (Video4Linux) through OpenCV: finding them in sysfs, opening a raw
16-bit (or YUYV) stream, and frames rebuilt from their bytes whatever shape the OpenCV build
hands them over in.

OpenCV's V4L2 backend returns a raw stream's buffer as a (rows, columns) uint16 image on some
builds and as its bytes, (1, N) or (N, 1) uint8, on others; with RGB conversion left on it
returns an 8-bit picture, from which no temperature can come. :func:`rebuild` checks the
shape and dtype of every frame, rebuilds it from its bytes where their number says which
frame it is, and raises one line naming the OpenCV version where it cannot.

Devices are found through sysfs (:func:`list_video_devices`): each ``/sys/class/video4linux/
video*`` capture node with its name and USB vendor:product, which tell the camera
(:data:`CAMERA_USB_IDS`, :data:`CAMERA_NAMES`).
"""

from __future__ import annotations

import errno
import fcntl
import os
import re
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from .base import DeviceGuard, DeviceLostError

SYSFS_VIDEO = Path("/sys/class/video4linux")
DEV_USB = Path("/dev/bus/usb")
USBDEVFS_RESET = 0x5514
"""``_IO('U', 20)`` of linux/usbdevice_fs.h: reset a USB device as if re-plugged."""

CAMERA_USB_IDS: dict[str, set[tuple[str, str]]] = {
    "lepton": {("1e4e", "0100")},  # GroupGets PureThermal 1/2/mini
    "p2pro": {("0bda", "5830")},  # InfiRay P2 Pro, Topdon TC001
    "boson": {("09cb", "4007")},  # FLIR Boson / Boson+
}
"""USB vendor:product of each thermal camera kind (the source spec's name)."""
CAMERA_NAMES: dict[str, str] = {"lepton": "purethermal", "boson": "boson"}
"""A word in a capture node's name that tells the kind where the USB id is not there."""
CAMERA_TITLES = {
    "lepton": "PureThermal (Lepton)",
    "p2pro": "InfiRay P2 Pro / Topdon TC001",
    "boson": "FLIR Boson",
}


def _read(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8", errors="replace").strip()
    except OSError:
        return ""


def camera_kind(name: str, usb_id: tuple[str, str] | None) -> str | None:
    """The thermal camera kind a capture node is (``lepton``, ``p2pro``, ``boson``), or None."""
    for kind, ids in CAMERA_USB_IDS.items():
        if usb_id in ids:
            return kind
    lower = name.lower()
    return next((k for k, word in CAMERA_NAMES.items() if word in lower), None)


def list_video_devices(sysfs: Path = SYSFS_VIDEO) -> list[dict[str, Any]]:
    """Every V4L2 capture node: ``index`` (N of /dev/videoN), ``name``, ``usb_id`` (vendor,
    product or None), ``kind`` (the thermal camera it is, or None) and ``purethermal``.
    Nodes with sysfs ``index`` > 0 (the metadata nodes UVC devices add) are left out. Robust
    to missing or unreadable sysfs files."""
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
        kind = camera_kind(name, usb_id)
        out.append(
            {
                "index": int(node.name[5:]),
                "name": name,
                "usb_id": usb_id,
                "kind": kind,
                "purethermal": kind == "lepton",
            }
        )
    return out


def list_cameras(kind: str, sysfs: Path = SYSFS_VIDEO) -> list[dict[str, Any]]:
    """The capture nodes of one thermal camera kind."""
    return [d for d in list_video_devices(sysfs) if d["kind"] == kind]


def list_purethermal(sysfs: Path = SYSFS_VIDEO) -> list[dict[str, Any]]:
    """The video devices that look like a PureThermal board."""
    return list_cameras("lepton", sysfs)


_DEVICE = re.compile(r"^(?:/dev/video)?(\d+)$")


def device_index(kind: str, arg: str, sysfs: Path = SYSFS_VIDEO) -> int:
    """The /dev/videoN number a spec's argument names (``2`` or ``/dev/video2``), or the first
    camera of ``kind`` found when it names none; one InputError line otherwise (naming the
    video devices there are)."""
    if arg:
        m = _DEVICE.match(arg)
        if m is None:
            raise InputError(
                f"{kind}:{arg}: expected a video device, N or /dev/videoN ({kind}:0 = /dev/video0)"
            )
        return int(m.group(1))
    found = list_cameras(kind, sysfs)
    if found:
        return int(found[0]["index"])
    others = ", ".join(
        f"/dev/video{d['index']} ({d['name'] or 'unnamed'})" for d in list_video_devices(sysfs)
    )
    raise InputError(
        f"no {CAMERA_TITLES[kind]} found"
        + (f"; video devices: {others}" if others else "; no video devices at all")
    )


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


def rebuild(
    raw: Any, shapes: Sequence[tuple[int, ...]], dtype: type[np.generic], name: str
) -> NDArray[Any]:
    """A frame as one of ``shapes`` of ``dtype`` (little-endian on the wire), from what
    OpenCV's read returned: the frame itself, or its bytes ((1, N), (N, 1), (N,) uint8)
    whose number says which shape it is. One InputError line naming ``name``, the shapes
    expected and the OpenCV version when it cannot be (an 8-bit picture: RGB conversion on,
    or a build that ignores turning it off)."""
    arr = np.asarray(raw)
    want = np.dtype(dtype)
    if arr.dtype == want and arr.shape in shapes:
        return arr
    if arr.size and (arr.dtype == np.uint8 or arr.ndim <= 1 or 1 in arr.shape[:2]):
        nbytes = arr.size * arr.itemsize
        for shape in shapes:
            if nbytes == int(np.prod(shape)) * want.itemsize:
                flat = np.ascontiguousarray(arr).reshape(-1).view(np.uint8)
                return flat.view(want.newbyteorder("<")).reshape(shape).astype(want)
    expected = " or ".join("x".join(str(s) for s in shape[1::-1]) for shape in shapes)
    raise InputError(
        f"{name}: OpenCV {cv2.__version__} returned a frame of shape {arr.shape} {arr.dtype}, "
        f"not a {expected} {want.name} frame nor its bytes: it converted the stream (is this "
        "the camera's raw format? RGB conversion must be off, which some OpenCV builds "
        "ignore: try opencv-python-headless from PyPI)"
    )


class UvcCapture:
    """A capture node opened raw through OpenCV (V4L2): ``fourcc`` (``"Y16 "``, ``"YUYV"``)
    at ``size`` (width, height; None: the device's default), RGB conversion off, a one-frame
    buffer where the driver allows it (the newest frame, not a queued one).

    :meth:`frames` yields (raw, arrival time) until :meth:`close`; a device that gives no
    frame for ``timeout_s`` (unplugged, or a board whose stream stopped) raises
    :class:`~.base.DeviceLostError`. ``close()`` may come from any thread
    (:class:`~.base.DeviceGuard`). An index that cannot be opened raises one InputError line.
    """

    def __init__(
        self,
        index: int,
        name: str,
        fourcc: str,
        size: tuple[int, int] | None = None,
        timeout_s: float = 3.0,
        latency_s: float = 0.0,
    ) -> None:
        self.index, self.name = index, name
        self.timeout_s, self.latency_s = timeout_s, latency_s
        device = Path(f"/dev/video{index}")
        with quiet_opencv():
            self.cap = cv2.VideoCapture(index, cv2.CAP_V4L2)
            if not self.cap.isOpened():
                why = "busy, or not a capture device" if device.exists() else "no such device"
                raise InputError(f"{device}: cannot open ({why})")
            self.cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*fourcc))
            self.cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
            if size is not None:
                self.cap.set(cv2.CAP_PROP_FRAME_WIDTH, size[0])
                self.cap.set(cv2.CAP_PROP_FRAME_HEIGHT, size[1])
            self.cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)
        self.device = str(device)
        self._guard = DeviceGuard(self.cap.release)

    def frames(self) -> Iterator[tuple[Any, float]]:
        """Each frame as OpenCV returns it, with its arrival time (``time.time()`` minus
        ``latency_s``); the device is released when this ends."""
        last_ok = time.monotonic()
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
                yield raw, now
        finally:
            self._guard.release()

    def close(self) -> None:
        """Stop reading; the device is released now, or by the reading thread as soon as its
        read returns (never under a read)."""
        self._guard.close()


def usb_device_node(index: int, sysfs: Path = SYSFS_VIDEO, devfs: Path = DEV_USB) -> Path | None:
    """The usbfs node (``/dev/bus/usb/BBB/DDD``) of the USB device /dev/videoN belongs to
    (its ``busnum`` and ``devnum`` in sysfs, above the video interface), or None."""
    device = sysfs / f"video{index}" / "device"
    for parent in (device, device / "..", device / "../.."):
        bus, dev = _read(parent / "busnum"), _read(parent / "devnum")
        if bus.isdigit() and dev.isdigit():
            return devfs / f"{int(bus):03d}" / f"{int(dev):03d}"
    return None


def usb_reset(index: int, name: str, sysfs: Path = SYSFS_VIDEO, devfs: Path = DEV_USB) -> str:
    """Reset the USB device of /dev/videoN (``USBDEVFS_RESET``), as a PureThermal board whose
    stream stopped needs; a line saying it was done, or why it could not be (no such
    device, or this process may not write its node: root, or a udev rule granting it)."""
    node = usb_device_node(index, sysfs, devfs)
    if node is None:
        return f"{name}: no USB reset: /dev/video{index} is not a USB device here"
    try:
        fd = os.open(node, os.O_WRONLY)
    except OSError as exc:
        why = (
            "this process may not write it (run as root, or grant it with a udev rule)"
            if exc.errno in (errno.EACCES, errno.EPERM)
            else exc.strerror or str(exc)
        )
        return f"{name}: no USB reset of {node}: {why}"
    try:
        fcntl.ioctl(fd, USBDEVFS_RESET, 0)
    except OSError as exc:
        return f"{name}: USB reset of {node} failed ({exc.strerror or exc})"
    finally:
        os.close(fd)
    return f"{name}: USB reset of {node}"


def frozen(image: NDArray[Any], previous: NDArray[Any] | None) -> bool:
    """True when ``image`` repeats ``previous`` exactly: a camera that holds its last image
    while its shutter is closed (FFC; an InfiRay P2 Pro, a Boson) does so, where a live
    sensor's noise makes two frames never equal."""
    return (
        previous is not None and image.shape == previous.shape and np.array_equal(image, previous)
    )


class UvcCamera:
    """What every thermal camera over UVC is: the first of its ``kind`` found unless an index
    is given, named ``kind:N``, live, read through a :class:`UvcCapture` (``fourcc`` at
    ``size``) and closed by it; ``warn`` is where its one-line warnings go."""

    kind: str = ""

    def __init__(
        self,
        index: int | None,
        fourcc: str,
        size: tuple[int, int] | None,
        timeout_s: float,
        latency_s: float,
        warn: Callable[[str], None] | None,
        sysfs: Path,
    ) -> None:
        if index is None:
            index = device_index(self.kind, "", sysfs)
        self.index = index
        self.name = f"{self.kind}:{index}"
        self.sysfs = sysfs
        self.live = True
        self.warn = warn or (lambda line: None)
        self.capture = UvcCapture(index, self.name, fourcc, size, timeout_s, latency_s)

    def close(self) -> None:
        """Stop reading; the device is released now, or by the reading thread as soon as its
        read returns (never under a read)."""
        self.capture.close()

    def recover(self) -> str:
        """A USB reset of the camera (:func:`usb_reset`)."""
        return usb_reset(self.index, self.name, self.sysfs)


def opened_channel(opened: Any, kind: type, warn: Callable[[str], None], why: str) -> Any:
    """``opened`` when it is a ``kind`` (a camera's command channel), else None after one
    warning: ``why`` with the reason ``opened`` gives in place of ``{reason}``."""
    if isinstance(opened, kind):
        return opened
    warn(why.format(reason=opened))
    return None
